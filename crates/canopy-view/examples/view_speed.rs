//! How quickly the viewer answers, measured as a page sees it (a WebSocket client in this
//! process): the first frame after start, the first frame after a camera move (the
//! preview) and the first full-size one, frames per second while the camera moves every
//! 16 ms (a drag), and the time to converge to 64 spp once it stops.
//!
//! `cargo run --release -p canopy-view --example view_speed -- [--size WxH] [--threads N]
//! [--device cpu|gpu] [SCENE...]` (default: paper-1, cornell and the glTF milk truck at 640x480). Times
//! include encoding and sending frames, as a user waits for them.

use canopy_job::Device;
use canopy_view::{ViewOptions, ViewServer};
use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;
type Receiver = futures_util::stream::SplitStream<Socket>;

/// The next frame's description (its image is read and dropped).
async fn next_frame(ws: &mut Receiver) -> Value {
    loop {
        match ws.next().await.expect("open").expect("no error") {
            Message::Text(text) => {
                let m: Value = serde_json::from_str(&text).unwrap();
                if m["type"] == "frame" {
                    // Its image follows.
                    ws.next().await.expect("open").expect("no error");
                    return m;
                }
            }
            _ => continue,
        }
    }
}

async fn frame_until(ws: &mut Receiver, done: impl Fn(&Value) -> bool) -> Value {
    loop {
        let f = next_frame(ws).await;
        if done(&f) {
            return f;
        }
    }
}

fn camera_command(hello: &Value, angle: f32) -> Value {
    let c = &hello["camera"];
    let v = |a: &Value| -> [f32; 3] { std::array::from_fn(|i| a[i].as_f64().unwrap() as f32) };
    let (from, at) = (v(&c["look_from"]), v(&c["look_at"]));
    let offset = [from[0] - at[0], from[1] - at[1], from[2] - at[2]];
    // Turned about the scene's up (y) by `angle`.
    let (s, co) = angle.sin_cos();
    let turned = [
        offset[0] * co + offset[2] * s,
        offset[1],
        -offset[0] * s + offset[2] * co,
    ];
    json!({
        "type": "camera",
        "look_from": [at[0] + turned[0], at[1] + turned[1], at[2] + turned[2]],
        "look_at": at,
        "up": c["up"],
        "vfov": c["vfov"],
    })
}

async fn measure(name: &str, size: (u32, u32), threads: Option<usize>, device: Device) {
    let mut scene = canopy_render::load_scene_allowing(name, &[]).unwrap();
    (scene.settings.width, scene.settings.height) = size;
    scene.settings.spp = 64;
    let started = Instant::now();
    let server = ViewServer::start(
        scene,
        ViewOptions {
            render: canopy_job::RenderOptions {
                threads,
                device: Some(device),
                ..Default::default()
            },
            ..ViewOptions::default()
        },
    )
    .unwrap();
    let url = format!("ws://{}/ws?token={}", server.addr(), server.token());
    let (socket, _) = tokio_tungstenite::connect_async(url).await.unwrap();
    let (mut tx, mut ws) = socket.split();
    let hello: Value = match ws.next().await.unwrap().unwrap() {
        Message::Text(t) => serde_json::from_str(&t).unwrap(),
        _ => panic!("no hello"),
    };
    let first = next_frame(&mut ws).await;
    let to_first = started.elapsed();
    assert_eq!(first["preview"], true);
    frame_until(&mut ws, |f| f["preview"] == false).await;

    // One camera move: the preview, then the first full-size pass.
    let moved = Instant::now();
    tx.send(Message::Text(
        camera_command(&hello, 0.05).to_string().into(),
    ))
    .await
    .unwrap();
    frame_until(&mut ws, |f| f["generation"].as_u64() >= Some(1)).await;
    let to_preview = moved.elapsed();
    frame_until(&mut ws, |f| f["preview"] == false).await;
    let to_full = moved.elapsed();

    // A drag: a move every 16 ms for two seconds, sent by a task of its own; frames
    // counted as they arrive.
    let drag = Duration::from_secs(2);
    let moves = (drag.as_millis() / 16) as u64;
    let sender = {
        let hello = hello.clone();
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_millis(16));
            for step in 1..=moves {
                tick.tick().await;
                let command = camera_command(&hello, 0.05 + 0.01 * step as f32);
                tx.send(Message::Text(command.to_string().into()))
                    .await
                    .unwrap();
            }
            tx
        })
    };
    let drag_start = Instant::now();
    let mut frames = 0u32;
    while drag_start.elapsed() < drag {
        if tokio::time::timeout(
            drag.saturating_sub(drag_start.elapsed()),
            next_frame(&mut ws),
        )
        .await
        .is_ok()
        {
            frames += 1;
        }
    }
    let fps = frames as f64 / drag_start.elapsed().as_secs_f64();
    let mut tx = sender.await.unwrap();

    // Stopped: time to 64 spp.
    let stopped = Instant::now();
    tx.send(Message::Text(
        camera_command(&hello, 1.0).to_string().into(),
    ))
    .await
    .unwrap();
    let last_generation = moves + 2;
    frame_until(&mut ws, |f| {
        f["generation"].as_u64() >= Some(last_generation) && f["spp"] == 64
    })
    .await;
    let to_converge = stopped.elapsed();
    if device == Device::Gpu {
        println!("on {}", hello["device_name"]);
    }
    println!(
        "{name:<32} first frame {:>7.1} ms | after a move: preview {:>6.1} ms, full size {:>6.1} ms | dragging {:>5.1} frames/s | 64 spp in {:>6.2} s",
        to_first.as_secs_f64() * 1e3,
        to_preview.as_secs_f64() * 1e3,
        to_full.as_secs_f64() * 1e3,
        fps,
        to_converge.as_secs_f64(),
    );
    server.shutdown();
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut size = (640, 480);
    let mut threads = None;
    let mut device = Device::Cpu;
    let mut scenes = Vec::new();
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--size" => {
                let s = args.next().expect("--size WxH");
                let (w, h) = s.split_once('x').expect("--size WxH");
                size = (w.parse().unwrap(), h.parse().unwrap());
            }
            "--threads" => threads = Some(args.next().unwrap().parse().unwrap()),
            "--device" => device = args.next().expect("--device cpu|gpu").parse().unwrap(),
            _ => scenes.push(arg),
        }
    }
    if scenes.is_empty() {
        scenes = ["paper-1", "cornell", "scenes/gltf/CesiumMilkTruck.glb"]
            .map(String::from)
            .to_vec();
    }
    println!(
        "canopy view, {}x{}, {} threads, CPU: {}",
        size.0,
        size.1,
        threads.unwrap_or_else(rayon::current_num_threads),
        cpu_model()
    );
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    for scene in &scenes {
        runtime.block_on(measure(scene, size, threads, device));
    }
}

fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_owned())
        })
        .unwrap_or_else(|| "unknown".into())
}
