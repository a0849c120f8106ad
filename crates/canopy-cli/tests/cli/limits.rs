//! Every numeric option of every subcommand at its limits: 0, the largest value allowed,
//! one past it, a negative number and NaN. Whatever the value: no panic, no hang, the
//! documented exit status (2 for a value out of range, naming the option), and no stray
//! files.
//!
//! Values in range are tried with an output that cannot be written (or a tiny input), so
//! that the largest ones are accepted by the parser and then refused by a cheap check
//! rather than rendering for days.

use crate::common;

use common::{canopy_within, scratch, stderr};
use std::time::Duration;

/// The subcommand and the arguments that make an in-range run end at once.
struct Command {
    base: &'static [&'static str],
    /// Status of a run with an in-range value.
    in_range_status: i32,
}

const RENDER: Command = Command {
    base: &["render", "paper-1", "-o", "missing/x.png"],
    in_range_status: 1,
};
const BVH: Command = Command {
    base: &["bvh", "cornell", "--bvh", "ploc"],
    in_range_status: 0,
};
const BENCH: Command = Command {
    base: &["bench", "paper", "--out", "file/out"],
    in_range_status: 1,
};

/// (option, zero is allowed, largest allowed, one past it).
type Limits = (&'static str, bool, &'static str, &'static str);

const BUILD: [Limits; 5] = [
    ("--max-leaf-size", false, "256", "257"),
    ("--max-duplication", true, "16", "16.5"),
    ("--sah-traversal", false, "1e6", "1.1e6"),
    ("--sah-intersection", false, "1e6", "1.1e6"),
    ("--ploc-radius", false, "1024", "1025"),
];

fn check(command: &Command, limits: &[Limits]) {
    let dir = scratch(&format!("limits-{}-{}", command.base[0], command.base[1]));
    std::fs::write(dir.join("file"), "a file, not a directory").unwrap();
    for &(option, zero_ok, max, past) in limits {
        let cases = [
            ("0", if zero_ok { command.in_range_status } else { 2 }),
            (max, command.in_range_status),
            (past, 2),
            ("-1", 2),
            ("nan", 2),
        ];
        for (value, status) in cases {
            let arg = format!("{option}={value}");
            let mut args = command.base.to_vec();
            args.push(&arg);
            let out = canopy_within(&args, &dir, Duration::from_secs(120));
            let err = stderr(&out);
            assert!(!err.contains("panicked"), "{args:?}: {err}");
            assert_eq!(out.status.code(), Some(status), "{args:?}: {err}");
            if status == 2 {
                assert!(
                    err.contains(option),
                    "{args:?} does not name the option: {err}"
                );
            }
            let mut files: Vec<String> = std::fs::read_dir(&dir)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            files.sort();
            assert_eq!(files, ["file"], "{args:?} left files behind");
        }
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn render_options_at_their_limits() {
    let mut limits = vec![
        ("--spp", false, "16777216", "16777217"),
        ("--depth", false, "1024", "1025"),
        ("--size", false, "65536x4096", "65537x1"),
        (
            "--seed",
            true,
            "18446744073709551615",
            "18446744073709551616",
        ),
        ("--threads", false, "1024", "1025"),
        ("--every", true, "8760h", "8761h"),
        (
            "--levels",
            true,
            "18446744073709551615",
            "18446744073709551616",
        ),
    ];
    limits.extend(BUILD);
    // --every and --levels need their companions.
    let with = |extra: &'static [&'static str]| Command {
        base: extra,
        in_range_status: 1,
    };
    check(&RENDER, &limits[..5]);
    check(
        &with(&[
            "render",
            "paper-1",
            "-o",
            "missing/x.png",
            "--checkpoint",
            "ck",
        ]),
        &limits[5..6],
    );
    check(
        &with(&["render", "paper-1", "-o", "missing/x.png", "--show-bvh"]),
        &limits[6..7],
    );
    check(&RENDER, &limits[7..]);
}

#[test]
fn bvh_options_at_their_limits() {
    let mut limits = vec![
        ("--runs", false, "1000", "1001"),
        ("--optimize", false, "1000", "1001"),
    ];
    limits.extend(BUILD);
    check(&BVH, &limits);
}

#[test]
fn bench_lights_options_at_their_limits() {
    let lights = Command {
        base: &["bench", "lights", "--out", "file/out.md"],
        in_range_status: 1,
    };
    check(
        &lights,
        &[
            ("--size", false, "65536x4096", "65537x1"),
            ("--seconds", true, "8760h", "8761h"),
            ("--reference-spp", false, "16777216", "16777217"),
            ("--threads", false, "1024", "1025"),
        ],
    );
}

#[test]
fn bench_options_at_their_limits() {
    let mut limits = vec![
        ("--runs", false, "1000", "1001"),
        ("--spp", false, "16777216", "16777217"),
        ("--size", false, "65536x4096", "65537x1"),
        ("--threads", false, "1024", "1025"),
        ("--scenes", false, "6", "7"),
    ];
    limits.extend(BUILD);
    check(&BENCH, &limits);
}

#[test]
fn view_options_at_their_limits() {
    // An address no interface has: a run in range stops at listening.
    let view = Command {
        base: &["view", "cornell", "--bind", "192.0.2.1:9"],
        in_range_status: 1,
    };
    check(
        &view,
        &[
            ("--spp", false, "16777216", "16777217"),
            ("--depth", false, "1024", "1025"),
            ("--size", false, "65536x4096", "65537x1"),
            ("--threads", false, "1024", "1025"),
            ("--max-leaf-size", false, "256", "257"),
        ],
    );
}
