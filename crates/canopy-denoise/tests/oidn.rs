//! The binding against the real library: a noisy image comes back closer to the clean
//! one, the same whatever the thread count. Where OIDN is not installed these tests say
//! so and pass, unless `CANOPY_REQUIRE_OIDN` is set (the test script sets it after
//! installing OIDN with `scripts/oidn.sh`).

use canopy_denoise::{Images, Oidn, Options};

fn oidn() -> Option<Oidn> {
    match Oidn::load(&[]) {
        Ok(oidn) => Some(oidn),
        Err(e) if std::env::var_os("CANOPY_REQUIRE_OIDN").is_some() => panic!("{e}"),
        Err(e) => {
            eprintln!("SKIPPED: {e}");
            None
        }
    }
}

/// A smooth image, and the same with noise of mean zero (a fixed hash, no rng crate).
fn images(width: usize, height: usize) -> (Vec<f32>, Vec<f32>) {
    let mut clean = Vec::with_capacity(width * height * 3);
    let mut noisy = Vec::with_capacity(width * height * 3);
    for y in 0..height {
        for x in 0..width {
            for c in 0..3 {
                let value = 0.2
                    + 0.6 * (x as f32 / width as f32) * (0.5 + c as f32 * 0.25)
                    + 0.1 * (y as f32 / height as f32);
                let hash = ((x * 73_856_093) ^ (y * 19_349_663) ^ (c * 83_492_791)) % 1000;
                clean.push(value);
                noisy.push(value * (0.4 + 1.2 * hash as f32 / 1000.0));
            }
        }
    }
    (clean, noisy)
}

fn mse(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64
}

#[test]
fn denoising_brings_a_noisy_image_closer_the_same_on_any_thread_count() {
    let Some(oidn) = oidn() else { return };
    let (width, height) = (64, 48);
    let (clean, noisy) = images(width, height);
    let albedo = vec![0.8f32; width * height * 3];
    let normal: Vec<f32> = (0..width * height).flat_map(|_| [0.0, 0.0, 1.0]).collect();
    let input = Images {
        width,
        height,
        color: &noisy,
        albedo: Some(&albedo),
        normal: Some(&normal),
    };
    let one = Options {
        threads: Some(1),
        ..Options::default()
    };
    let denoised = oidn.denoise(&input, &one).unwrap();
    let (before, after) = (mse(&noisy, &clean), mse(&denoised, &clean));
    eprintln!("MSE {before:.5} noisy, {after:.5} denoised");
    assert!(after < before / 4.0, "MSE {before} noisy, {after} denoised");
    let two = Options {
        threads: Some(2),
        ..Options::default()
    };
    assert_eq!(oidn.denoise(&input, &two).unwrap(), denoised);
    // Colour alone, and with the guides prefiltered: both work.
    let colour_only = Images {
        albedo: None,
        normal: None,
        ..input
    };
    let alone = oidn.denoise(&colour_only, &one).unwrap();
    assert!(mse(&alone, &clean) < before / 4.0);
    let prefiltered = Options {
        prefilter: true,
        ..one
    };
    assert!(mse(&oidn.denoise(&input, &prefiltered).unwrap(), &clean) < before / 4.0);
}
