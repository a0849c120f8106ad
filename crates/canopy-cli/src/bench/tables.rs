//! The results of `canopy bench paper` as Markdown, CSV and JSON.

use super::Measurement;
use std::fmt::Write;

/// `x` with four significant digits (render times span microseconds to minutes).
pub fn significant(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let decimals = (3 - x.abs().log10().floor() as i32).max(0) as usize;
    format!("{x:.decimals$}")
}

/// `mean ± std`, both to the mean's precision.
fn mean_and_spread(mean: f64, std: f64) -> String {
    let mean_text = significant(mean);
    let decimals = mean_text.split_once('.').map_or(0, |(_, d)| d.len());
    format!("{mean_text} ± {std:.decimals$}")
}

/// One CSV line per measurement, with a header.
pub fn csv(measurements: &[Measurement]) -> String {
    let mut out = String::from(
        "scene,method,builder,width,runs,mean_s,std_s,speedup,report_mean_s,report_speedup,build_ms,sah_cost,rays,mrays_per_s,nodes_per_ray,prims_per_ray\n",
    );
    for m in measurements {
        let opt = |v: Option<f64>| v.map(|v| format!("{v:.4}")).unwrap_or_default();
        writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{:.3},{:.3},{},{:.3},{:.2},{:.2}",
            m.scene,
            m.method,
            m.builder,
            m.width,
            m.seconds.len(),
            significant(m.mean_s),
            significant(m.std_s),
            opt(m.speedup),
            opt(m.report_mean_s),
            opt(m.report_speedup),
            m.build_ms,
            m.sah_cost,
            m.rays,
            m.mrays_per_s,
            m.nodes_per_ray,
            m.prims_per_ray
        )
        .expect("writing to a String");
    }
    out
}

/// The Markdown report: settings, Table 1 (times), Table 2 (speedups, the report's in
/// brackets) and, per scene, build time, tree quality and traversal work.
pub fn markdown(measurements: &[Measurement], settings: &str, command: &str) -> String {
    let mut scenes: Vec<&str> = Vec::new();
    let mut methods: Vec<&str> = Vec::new();
    for m in measurements {
        if !scenes.contains(&m.scene.as_str()) {
            scenes.push(&m.scene);
        }
        if !methods.contains(&m.method.as_str()) {
            methods.push(&m.method);
        }
    }
    let find = |scene: &str, method: &str| {
        measurements
            .iter()
            .find(|m| m.scene == scene && m.method == method)
    };
    let mut md = String::new();
    let w = &mut md;
    let _ = writeln!(
        w,
        "# canopy bench paper\n\n{settings}\n\nReproduce with `{command}`.\n"
    );
    let header = |w: &mut String, first: &str| {
        let _ = writeln!(w, "| {first} | {} |", scenes.join(" | "));
        let _ = writeln!(w, "|---|{}", "---|".repeat(scenes.len()));
    };

    let _ = writeln!(
        w,
        "## Table 1: render time, mean ± standard deviation (s)\n"
    );
    header(w, "method");
    for method in &methods {
        let cells: Vec<String> = scenes
            .iter()
            .map(|s| find(s, method).map_or("–".into(), |m| mean_and_spread(m.mean_s, m.std_s)))
            .collect();
        let _ = writeln!(w, "| {method} | {} |", cells.join(" | "));
    }

    let _ = writeln!(
        w,
        "\n## Table 2: speedup over no BVH (the report's own, on its 2009 Xeon, in brackets)\n"
    );
    header(w, "method");
    for method in &methods {
        let cells: Vec<String> = scenes
            .iter()
            .map(|s| match find(s, method) {
                Some(m) => {
                    let measured = m.speedup.map_or("–".into(), |x| format!("{x:.2}x"));
                    match m.report_speedup {
                        Some(r) => format!("{measured} ({r:.2}x)"),
                        None => measured,
                    }
                }
                None => "–".into(),
            })
            .collect();
        let _ = writeln!(w, "| {method} | {} |", cells.join(" | "));
    }

    let _ = writeln!(
        w,
        "\n## Build time, tree quality and traversal work\n\nSAH cost is normalised to the root box; node visits and primitive tests are per ray, over all rays of a 1-spp render.\n"
    );
    for scene in &scenes {
        let _ = writeln!(w, "### {scene}\n");
        let _ = writeln!(
            w,
            "| method | build ms | SAH cost | Mrays/s | nodes/ray | prims/ray |"
        );
        let _ = writeln!(w, "|---|---|---|---|---|---|");
        for method in &methods {
            if let Some(m) = find(scene, method) {
                let _ = writeln!(
                    w,
                    "| {method} | {:.2} | {:.2} | {:.2} | {:.1} | {:.1} |",
                    m.build_ms, m.sah_cost, m.mrays_per_s, m.nodes_per_ray, m.prims_per_ray
                );
            }
        }
        let _ = writeln!(w);
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_significant_digits() {
        assert_eq!(significant(102.94), "102.9");
        assert_eq!(significant(0.0012346), "0.001235");
        assert_eq!(significant(28.0), "28.00");
        assert_eq!(significant(12345.6), "12346");
        assert_eq!(significant(0.0), "0");
    }
}
