//! The ranges of the command line's numbers, checked by the parser so that a value out of
//! range is a usage error (exit 2) that names the option and the range, before any work.

use canopy_render::RenderSettings;
use std::time::Duration;

/// Most worker threads: far above any core count canopy runs on, low enough that the
/// threads' stacks and start-up are never the cost of a render.
pub const MAX_THREADS: u32 = 1024;
/// Widest or tallest image, in pixels.
pub const MAX_SIDE: u32 = 1 << 16;
/// Most neighbours PLOC searches on each side (the literature uses 8 to 100).
pub const MAX_PLOC_RADIUS: u32 = 1024;
/// Most primitives in a BVH leaf.
pub const MAX_LEAF_SIZE: u32 = 256;
/// Largest relative SAH cost.
pub const MAX_SAH_COST: f32 = 1e6;
/// Most repetitions of a measurement.
pub const MAX_RUNS: u32 = 1000;

/// Peak bytes per pixel of a render (checked again by the render job).
pub use canopy_job::BYTES_PER_PIXEL;

pub fn threads() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=MAX_THREADS as i64)
}

pub fn spp() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=RenderSettings::MAX_SPP as i64)
}

pub fn depth() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=RenderSettings::MAX_DEPTH as i64)
}

pub fn runs() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=MAX_RUNS as i64)
}

pub fn ploc_radius() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=MAX_PLOC_RADIUS as i64)
}

pub fn leaf_size() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=MAX_LEAF_SIZE as i64)
}

/// A relative SAH cost: a finite number in (0, MAX_SAH_COST].
pub fn sah_cost(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(c) if c > 0.0 && c <= MAX_SAH_COST => Ok(c),
        _ => Err(format!("`{s}` is not a number in (0, {MAX_SAH_COST:e}]")),
    }
}

/// A duplication budget for spatial splits, as [`canopy_bvh::BuildParams::check`] allows.
pub fn max_duplication(s: &str) -> Result<f32, String> {
    let refused = || format!("`{s}` is not a number from 0 to 16");
    let d = s.trim().parse::<f32>().map_err(|_| refused())?;
    let params = canopy_bvh::BuildParams {
        max_duplication: d,
        ..Default::default()
    };
    params.check().map(|_| d).map_err(|_| refused())
}

/// Longest interval between checkpoint saves: a year.
pub const MAX_INTERVAL: Duration = Duration::from_secs(365 * 24 * 3600);

/// A duration: seconds, or a number with s, m or h, from 0 to [`MAX_INTERVAL`].
pub fn duration(s: &str) -> Result<Duration, String> {
    let (number, unit) = match s.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((i, _)) => s.split_at(i),
        None => (s, "s"),
    };
    let scale = match unit {
        "s" => 1.0,
        "m" => 60.0,
        "h" => 3600.0,
        _ => return Err(format!("`{s}`: use seconds, or a number with s, m or h")),
    };
    let seconds = number.trim().parse::<f64>().map(|n| n * scale);
    match seconds {
        Ok(secs) if (0.0..=MAX_INTERVAL.as_secs_f64()).contains(&secs) => {
            Ok(Duration::from_secs_f64(secs))
        }
        _ => Err(format!("`{s}` is not a duration from 0 to 8760h")),
    }
}

/// `WIDTHxHEIGHT`, each side in 1..=MAX_SIDE and the image within
/// [`RenderSettings::MAX_PIXELS`].
pub fn size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WIDTHxHEIGHT"))?;
    let side = |d: &str| {
        d.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=MAX_SIDE).contains(v))
    };
    let (Some(w), Some(h)) = (side(w), side(h)) else {
        return Err(format!(
            "`{s}`: width and height must be whole numbers in 1..={MAX_SIDE}"
        ));
    };
    if w as u64 * h as u64 > RenderSettings::MAX_PIXELS {
        return Err(format!(
            "`{s}` has more than {} pixels",
            RenderSettings::MAX_PIXELS
        ));
    }
    Ok((w, h))
}

/// `--optimize`: passes (`3`) or a time (`500ms`, `2s`).
pub fn optimize_budget(s: &str) -> Result<canopy_bvh::OptimizeBudget, String> {
    if let Ok(passes) = s.parse::<u32>() {
        return match passes {
            1..=1000 => Ok(canopy_bvh::OptimizeBudget::Passes(passes)),
            _ => Err(format!("{passes} passes is not in 1..=1000")),
        };
    }
    let seconds = if let Some(ms) = s.strip_suffix("ms") {
        ms.parse::<f64>().map(|v| v / 1e3)
    } else if let Some(sec) = s.strip_suffix('s') {
        sec.parse::<f64>()
    } else {
        return Err(format!("`{s}`: expected passes (3) or a time (500ms, 2s)"));
    }
    .map_err(|_| format!("`{s}`: expected passes (3) or a time (500ms, 2s)"))?;
    if !(seconds > 0.0 && seconds <= 3600.0) {
        return Err(format!("`{s}`: the time must be in (0, 1h]"));
    }
    Ok(canopy_bvh::OptimizeBudget::Time(
        std::time::Duration::from_secs_f64(seconds),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_checked_side_by_side_and_in_total() {
        assert_eq!(size("640x480"), Ok((640, 480)));
        assert_eq!(size(" 3 X 2 "), Ok((3, 2)));
        for bad in [
            "0x4",
            "4x0",
            "-1x4",
            "65537x1",
            "x",
            "4",
            "65536x65536",
            "nanx1",
        ] {
            assert!(size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn durations_are_bounded_and_never_panic() {
        assert_eq!(duration("90"), Ok(Duration::from_secs(90)));
        assert_eq!(duration("1.5m"), Ok(Duration::from_secs(90)));
        assert_eq!(duration("8760h"), Ok(MAX_INTERVAL));
        for bad in ["8761h", "1e30h", "-1", "nan", "infs", "3d", ""] {
            assert!(duration(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn sah_costs_must_be_positive_and_finite() {
        assert_eq!(sah_cost("1.5"), Ok(1.5));
        for bad in ["0", "-1", "nan", "inf", "1e7", ""] {
            assert!(sah_cost(bad).is_err(), "{bad}");
        }
    }
}
