//! `canopy view`: the address it prints serves the page with its token and refuses it
//! without; Ctrl-C ends it at once.

use crate::common::{canopy_within, scratch, spawn, stderr};
use std::io::{BufRead, BufReader, Read, Write};
use std::process::Command;
use std::time::Duration;

fn get(addr: &str, path: &str) -> u16 {
    let mut stream = std::net::TcpStream::connect(addr).unwrap();
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).unwrap();
    response.split_whitespace().nth(1).unwrap().parse().unwrap()
}

#[test]
fn view_prints_an_address_that_serves_the_page_and_ends_on_ctrl_c() {
    let dir = scratch("view");
    let mut child = spawn(
        &["view", "cornell", "--size", "32x32", "--threads", "1"],
        &dir,
    );
    let stdout = BufReader::new(child.stdout.take().unwrap());
    // The address is on the line after the scene's.
    let url = stdout
        .lines()
        .map(|l| l.unwrap())
        .find(|l| l.trim_start().starts_with("http://"))
        .expect("canopy view prints its address");
    let url = url.trim();
    let rest = url.strip_prefix("http://").unwrap();
    let (addr, path) = rest.split_at(rest.find('/').unwrap());
    assert!(addr.starts_with("127.0.0.1:"), "bound to loopback: {url}");
    assert!(path.starts_with("/?token="));
    assert_eq!(get(addr, path), 200);
    assert_eq!(get(addr, "/"), 403);
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    assert!(!stderr(&out).contains("panicked"));
    assert!(
        std::fs::read_dir(&dir).unwrap().next().is_none(),
        "files left behind"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn view_refuses_an_address_it_cannot_listen_on_and_a_missing_output_folder() {
    let dir = scratch("view-refusals");
    for (args, message) in [
        // TEST-NET-1: assigned to no interface here.
        (
            &["view", "cornell", "--bind", "192.0.2.1:9"],
            "cannot listen on 192.0.2.1:9",
        ),
        (
            &["view", "cornell", "--output-dir", "missing"],
            "missing: --output-dir must be an existing folder",
        ),
    ] {
        let out = canopy_within(args, &dir, Duration::from_secs(120));
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        assert!(stderr(&out).contains(message), "{args:?}: {}", stderr(&out));
    }
    assert!(
        std::fs::read_dir(&dir).unwrap().next().is_none(),
        "files left behind"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn view_on_the_gpu_refuses_a_tree_the_gpu_cannot_walk_before_opening_it() {
    let dir = scratch("view-gpu-width");
    let args = ["view", "cornell", "--device", "gpu", "--width", "8"];
    let out = canopy_within(&args, &dir, Duration::from_secs(120));
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("`width` 8 is for the CPU"),
        "{}",
        stderr(&out)
    );
    std::fs::remove_dir_all(dir).unwrap();
}
