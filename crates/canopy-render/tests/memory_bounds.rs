//! The memory a mesh file takes to load is at most what canopy checks before loading it:
//! the peak of every allocation made while the worst case of each format loads (counted
//! by this binary's allocator) stays under [`MeshFormat::load_bytes_per_file_byte`]
//! times the file's size.

use canopy_render::mesh::MeshFormat;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// The system allocator, keeping the bytes in use and their peak.
struct Counting;

static IN_USE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let now = IN_USE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
        PEAK.fetch_max(now, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        IN_USE.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let now = IN_USE.fetch_add(new_size, Ordering::Relaxed) + new_size;
        PEAK.fetch_max(now, Ordering::Relaxed);
        let moved = unsafe { System.realloc(ptr, layout, new_size) };
        IN_USE.fetch_sub(layout.size(), Ordering::Relaxed);
        moved
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// One measurement at a time: the counters are the whole process's.
static MEASURING: Mutex<()> = Mutex::new(());

/// Bytes allocated at the peak of loading `path` as a scene, beyond what was in use
/// before.
fn peak_of_loading(path: &std::path::Path) -> usize {
    let _one = MEASURING.lock().unwrap_or_else(|p| p.into_inner());
    let before = IN_USE.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let scene = canopy_render::load_scene(path.to_str().unwrap());
    let peak = PEAK.load(Ordering::Relaxed) - before;
    drop(scene);
    peak
}

/// Files that cost the most memory per byte in each format: faces of the fewest bytes
/// (fans of one-character references, one-byte PLY counts and indices), vertices of the
/// fewest bytes.
fn worst_cases() -> Vec<(&'static str, MeshFormat, Vec<u8>)> {
    const N: usize = 60_000;
    let mut cases = Vec::new();
    // OBJ: a fan whose every reference is one digit.
    let mut fan =
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 1 0\nv 1 2 0\nv 2 2 0\nv 3 2 0\nv 2 3 0\nf 1"
            .to_vec();
    for i in 0..N {
        fan.extend(format!(" {}", 2 + i % 8).as_bytes());
    }
    fan.push(b'\n');
    cases.push(("obj fan", MeshFormat::Obj, fan));
    // OBJ: many one-digit triangles.
    let mut small = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n".to_vec();
    for i in 0..N / 4 {
        small.extend(if i % 2 == 0 {
            b"f 1 2 3\n"
        } else {
            b"f 2 4 3\n"
        });
    }
    cases.push(("obj triangles", MeshFormat::Obj, small));
    // OBJ: many short vertices, each used.
    let mut vertices = Vec::new();
    for _ in 0..N / 3 {
        vertices.extend(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n");
    }
    for i in 0..N / 3 {
        vertices.extend(format!("f {} {} {}\n", 3 * i + 1, 3 * i + 2, 3 * i + 3).as_bytes());
    }
    cases.push(("obj vertices", MeshFormat::Obj, vertices));
    // Binary PLY: fans of 255 one-byte indices behind one-byte counts.
    let fans = N / 255;
    let mut ply = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex 256\nproperty float x\nproperty float y\nproperty float z\n\
element face {fans}\nproperty list uchar uchar vertex_indices\nend_header\n"
    )
    .into_bytes();
    for v in 0..256u32 {
        let angle = v as f32 * 0.02;
        for c in [angle.cos(), angle.sin(), 0.0f32] {
            ply.extend(c.to_le_bytes());
        }
    }
    for f in 0..fans {
        ply.push(255);
        ply.extend((0..255u32).map(|i| ((i + f as u32) % 256) as u8));
    }
    cases.push(("binary ply fans", MeshFormat::Ply, ply));
    // ASCII PLY: short triangles.
    let tris = N / 4;
    let mut ascii = format!(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
element face {tris}\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n"
    )
    .into_bytes();
    for i in 0..tris {
        ascii.extend(if i % 2 == 0 {
            b"3 0 1 2\n"
        } else {
            b"3 1 3 2\n"
        });
    }
    cases.push(("ascii ply triangles", MeshFormat::Ply, ascii));
    // ASCII PLY: one fan of one-digit indices.
    let mut ascii_fan = String::from(
        "ply\nformat ascii 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\n\
element face 1\nproperty list int int vertex_indices\nend_header\n"
    )
    .into_bytes();
    for v in 0..10 {
        ascii_fan.extend(
            format!("{} {} 0\n", (v as f32 * 0.6).cos(), (v as f32 * 0.6).sin()).as_bytes(),
        );
    }
    ascii_fan.extend(format!("{N}").as_bytes());
    for i in 0..N {
        ascii_fan.extend(format!(" {}", i % 10).as_bytes());
    }
    ascii_fan.push(b'\n');
    cases.push(("ascii ply fan", MeshFormat::Ply, ascii_fan));
    cases
}

#[test]
fn loading_a_mesh_never_takes_more_memory_than_its_check_counts() {
    let dir = std::env::temp_dir().join(format!("canopy-memory-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut report = Vec::new();
    for (name, format, bytes) in worst_cases() {
        let ext = match format {
            MeshFormat::Obj => "obj",
            MeshFormat::Ply => "ply",
        };
        let path = dir.join(format!("{}.{ext}", name.replace(' ', "-")));
        std::fs::write(&path, &bytes).unwrap();
        let peak = peak_of_loading(&path);
        let per_byte = peak as f64 / bytes.len() as f64;
        report.push(format!("{name}: {per_byte:.1} bytes per file byte"));
        assert!(
            peak as u64 <= bytes.len() as u64 * format.load_bytes_per_file_byte(),
            "{name}: loading {} bytes peaked at {peak} bytes ({per_byte:.1} per byte), more than the {} per byte checked",
            bytes.len(),
            format.load_bytes_per_file_byte()
        );
    }
    eprintln!("{}", report.join("\n"));
    std::fs::remove_dir_all(dir).unwrap();
}
