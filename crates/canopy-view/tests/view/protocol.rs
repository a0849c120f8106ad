//! The viewer's protocol over a real socket: the token, frames, camera moves, rebuilds,
//! picks, hostile messages, slow clients and the last page closing. Every wait is on a
//! message or a state, never a fixed time (the timeouts only end a failing test).

use canopy_job::RenderOptions;
use canopy_view::{ViewOptions, ViewServer};
use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use std::io::{Read, Write};
use std::time::Duration;
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

/// Long enough for a loaded machine; only a failing test waits this long.
const PATIENCE: Duration = Duration::from_secs(120);

/// Options that render on two threads.
fn two_threads() -> RenderOptions {
    RenderOptions {
        threads: Some(2),
        ..RenderOptions::default()
    }
}

/// A small image of the first reference scene (spheres, a few lights).
fn server(width: u32, height: u32, spp: u32) -> ViewServer {
    server_of("paper-1", width, height, spp)
}

/// A small image of the built-in scene `name`, on two threads.
fn server_of(name: &str, width: u32, height: u32, spp: u32) -> ViewServer {
    let mut scene = canopy_render::load_scene(name).unwrap();
    scene.settings.width = width;
    scene.settings.height = height;
    scene.settings.spp = spp;
    scene.settings.max_depth = 4;
    let options = ViewOptions {
        render: two_threads(),
        ..ViewOptions::default()
    };
    ViewServer::start(scene, options).unwrap()
}

/// `GET path` over plain HTTP; the status code and body.
fn http_get(server: &ViewServer, path: &str) -> (u16, String) {
    let mut stream = std::net::TcpStream::connect(server.addr()).unwrap();
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
        server.addr()
    )
    .unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).unwrap();
    let status = response.split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, response)
}

type Socket = WebSocketStream<MaybeTlsStream<TcpStream>>;

struct Client {
    ws: Socket,
    /// The first message, sent on connection.
    hello: Value,
}

enum Received {
    Json(Value),
    Image(Vec<u8>),
}

impl Client {
    async fn connect(server: &ViewServer) -> Client {
        let url = format!("ws://{}/ws?token={}", server.addr(), server.token());
        let (ws, _) = tokio_tungstenite::connect_async(url).await.unwrap();
        Self::after_handshake(ws).await
    }

    async fn after_handshake(ws: Socket) -> Client {
        let mut client = Client {
            ws,
            hello: Value::Null,
        };
        let Received::Json(hello) = client.next().await else {
            panic!("the first message is not JSON");
        };
        assert_eq!(hello["type"], "hello");
        client.hello = hello;
        client
    }

    async fn next(&mut self) -> Received {
        loop {
            let message = tokio::time::timeout(PATIENCE, self.ws.next())
                .await
                .expect("no message in time")
                .expect("the socket closed")
                .expect("a socket error");
            match message {
                Message::Text(text) => return Received::Json(serde_json::from_str(&text).unwrap()),
                Message::Binary(bytes) => return Received::Image(bytes.to_vec()),
                _ => continue,
            }
        }
    }

    async fn send(&mut self, command: Value) {
        self.ws
            .send(Message::Text(command.to_string().into()))
            .await
            .unwrap();
    }

    /// The next message of type `kind` (frames' images skipped).
    async fn next_of(&mut self, kind: &str) -> Value {
        let wait = async {
            loop {
                if let Received::Json(m) = self.next().await {
                    if m["type"] == kind {
                        return m;
                    }
                }
            }
        };
        tokio::time::timeout(PATIENCE, wait)
            .await
            .unwrap_or_else(|_| panic!("no {kind} message in time"))
    }

    /// The next message of each of `kinds`, in whatever order they come.
    async fn next_of_each(&mut self, kinds: &[&str]) -> Vec<Value> {
        let mut found = vec![Value::Null; kinds.len()];
        while found.iter().any(Value::is_null) {
            let Received::Json(m) = self.next().await else {
                continue;
            };
            if let Some(i) = kinds.iter().position(|k| m["type"] == *k) {
                found[i] = m;
            }
        }
        found
    }

    /// The next frame and its decoded image.
    async fn frame(&mut self) -> (Value, image::RgbImage) {
        let info = self.next_of("frame").await;
        let Received::Image(bytes) = self.next().await else {
            panic!("a frame's image did not follow it");
        };
        let image = image::load_from_memory(&bytes).unwrap().to_rgb8();
        (info, image)
    }

    /// Frames until one satisfies `done`.
    async fn frame_until(&mut self, done: impl Fn(&Value) -> bool) -> (Value, image::RgbImage) {
        loop {
            let frame = self.frame().await;
            if done(&frame.0) {
                return frame;
            }
        }
    }
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
}

#[test]
fn every_request_needs_the_token() {
    let server = server(32, 24, 2);
    assert!(server.url().contains(server.token()));
    assert_eq!(server.token().len(), 32);
    let (status, body) = http_get(&server, &format!("/?token={}", server.token()));
    assert_eq!(status, 200);
    assert!(body.contains("canopy view"));
    assert_eq!(http_get(&server, "/").0, 403);
    assert_eq!(http_get(&server, "/?token=0123").0, 403);
    let mut wrong = server.token().to_string();
    wrong.replace_range(0..1, if wrong.starts_with('a') { "b" } else { "a" });
    assert_eq!(http_get(&server, &format!("/?token={wrong}")).0, 403);
    runtime().block_on(async {
        for url in [
            format!("ws://{}/ws", server.addr()),
            format!("ws://{}/ws?token={wrong}", server.addr()),
        ] {
            let refused = tokio_tungstenite::connect_async(url).await;
            assert!(refused.is_err(), "a socket without the token was accepted");
        }
    });
    assert_eq!(server.clients(), 0);
}

#[test]
fn frames_arrive_and_refine_to_the_target() {
    let server = server(48, 32, 6);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        assert_eq!(page.hello["width"], 48);
        assert_eq!(page.hello["settings"]["render"]["spp"], 6);
        assert_eq!(page.hello["settings"]["render"]["bvh"], "binned-sah");
        // A preview at a quarter of the size first, then full-size passes 1..=6. (A
        // page that reads more slowly than passes are made skips frames, the preview
        // among them: only what arrives is checked.)
        let mut spp = 0;
        while spp < 6 {
            let (info, image) = page.frame().await;
            let size = (image.width(), image.height());
            if info["preview"] == true {
                assert_eq!(spp, 0, "a preview after full-size frames");
                assert_eq!(size, (12, 8));
                continue;
            }
            assert_eq!(size, (48, 32));
            let now = info["spp"].as_u64().unwrap();
            assert!(now > spp, "samples went from {spp} to {now}");
            assert_eq!(info["target_spp"], 6);
            spp = now;
        }
        assert_eq!(spp, 6);
        // Every sample in: the render thread waits.
        wait_until(|| !server.is_rendering()).await;
    });
}

#[test]
fn a_camera_move_restarts_accumulation_and_other_tabs_see_it() {
    let server = server(160, 120, 1000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        let (before, _) = page.frame_until(|f| f["spp"].as_u64() >= Some(24)).await;
        let generation = before["generation"].as_u64().unwrap();
        let mut camera = page.hello["camera"].clone();
        camera["type"] = json!("camera");
        camera["look_from"][0] = json!(camera["look_from"][0].as_f64().unwrap() + 1.0);
        page.send(camera.clone()).await;
        let (after, image) = page
            .frame_until(|f| f["generation"].as_u64() > Some(generation))
            .await;
        // The preview, unless this page read too slowly to see it (frames are skipped,
        // not queued); either way accumulation starts again.
        if after["preview"] == true {
            assert_eq!((image.width(), image.height()), (40, 30));
        }
        let (full, _) = page.frame_until(|f| f["preview"] == false).await;
        assert!(
            full["spp"].as_u64() < Some(12),
            "accumulation went on from {} samples to {}",
            before["spp"],
            full["spp"]
        );
        // A second tab joins the same session: the moved camera.
        let second = Client::connect(&server).await;
        assert_eq!(second.hello["camera"]["look_from"], camera["look_from"]);
    });
}

#[test]
fn a_rebuild_changes_the_tree_statistics() {
    let server = server(32, 24, 1000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        let first = page.next_of("tree").await;
        assert_eq!(first["builder"], "binned-sah");
        assert_eq!(first["width"], 8);
        assert!(first["nodes"].as_u64() > Some(0));
        assert!(first["sah"].as_f64() > Some(0.0));
        page.send(json!({"type": "settings", "render": {"bvh": "sort-x", "width": 2, "max_leaf_size": 1}}))
            .await;
        let second = page.next_of("tree").await;
        assert_eq!(second["builder"], "sort-x");
        assert_eq!(second["width"], 2);
        assert_eq!(second["max_leaf_size"], 1);
        assert!(second["nodes"].as_u64() > first["nodes"].as_u64());
        assert!(
            second["sah"].as_f64() > first["sah"].as_f64(),
            "sorting by x alone is worse"
        );
        // Frames go on through the new tree.
        page.frame().await;
    });
}

/// The viewer starts with the render options every front end takes, shows them, and
/// refuses, before it listens, those it cannot honour.
#[test]
fn the_viewer_starts_with_the_render_options_it_is_given() {
    let scene = canopy_render::load_scene("paper-1").unwrap();
    let options = |render: RenderOptions| ViewOptions {
        render: RenderOptions {
            threads: Some(2),
            ..render
        },
        ..ViewOptions::default()
    };
    let given = RenderOptions::from_json(
        r#"{"size": [24, 16], "spp": 5, "seed": 9, "sampler": "independent", "bvh": "sweep-sah", "width": 4, "max_leaf_size": 2, "fast_triangles": true, "schedule": "depth"}"#,
    )
    .unwrap();
    let server = ViewServer::start(scene.clone(), options(given)).unwrap();
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        assert_eq!(
            (page.hello["width"].clone(), page.hello["height"].clone()),
            (json!(24), json!(16))
        );
        let shown = &page.hello["settings"]["render"];
        for (name, value) in [
            ("spp", json!(5)),
            ("seed", json!(9)),
            ("sampler", json!("independent")),
            ("bvh", json!("sweep-sah")),
            ("width", json!(4)),
            ("max_leaf_size", json!(2)),
            ("fast_triangles", json!(true)),
            ("schedule", json!("depth")),
        ] {
            assert_eq!(shown[name], value, "{name}");
        }
        let tree = page.next_of("tree").await;
        assert_eq!(
            (tree["builder"].clone(), tree["width"].clone()),
            (json!("sweep-sah"), json!(4))
        );
    });
    drop(server);
    for refused in [
        // The GPU walks binary trees.
        r#"{"device": "gpu", "width": 4}"#,
        r#"{"bvh": "none"}"#,
        r#"{"spp": 0}"#,
        r#"{"max_leaf_size": 1000}"#,
    ] {
        let render = RenderOptions::from_json(refused).unwrap();
        assert!(
            ViewServer::start(scene.clone(), options(render)).is_err(),
            "{refused}"
        );
    }
}

/// Another tree of the same triangle test gives the same hits: the image keeps its
/// samples. Another triangle test may not: accumulation starts again.
#[test]
fn another_tree_keeps_the_samples_and_another_triangle_test_restarts_them() {
    let server = server(32, 24, 1000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        // What the first full-size frame after the change continued from (a page that
        // reads slowly skips frames, but each says where its accumulation began).
        let continued_from = async |page: &mut Client, settings: Value| {
            let (before, _) = page.frame_until(|f| f["spp"].as_u64() >= Some(4)).await;
            let generation = before["generation"].as_u64();
            page.send(json!({"type": "settings", "render": settings}))
                .await;
            let (after, _) = page
                .frame_until(|f| f["generation"].as_u64() > generation && f["preview"] == false)
                .await;
            let from = after["continued_from"].as_u64().unwrap();
            (before["spp"].as_u64().unwrap(), from)
        };
        let (before, from) = continued_from(&mut page, json!({"bvh": "lbvh", "width": 4})).await;
        assert!(
            from >= before,
            "another tree: {before} samples, continued from {from}"
        );
        let (before, from) = continued_from(&mut page, json!({"fast_triangles": true})).await;
        assert_eq!(from, 0, "another triangle test after {before} samples");
    });
}

#[test]
fn a_pick_walks_the_tree_to_the_hit() {
    let server = server(48, 32, 1000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        page.next_of("tree").await;
        // The middle of the first reference scene is a sphere.
        page.send(json!({"type": "pick", "x": 24, "y": 16})).await;
        let walk = page.next_of("walk").await;
        let steps = walk["steps"].as_array().unwrap();
        assert!(!steps.is_empty());
        assert_eq!(steps[0]["level"], 0, "the walk starts at the root");
        let hit = &walk["hit"];
        assert!(hit["t"].as_f64() > Some(0.0));
        let prim = hit["primitive"].as_u64().unwrap();
        let in_a_leaf = steps
            .iter()
            .filter_map(|s| s["leaf"].as_array())
            .flatten()
            .any(|p| p.as_u64() == Some(prim));
        assert!(in_a_leaf, "the hit primitive is in a leaf the walk tested");
        // A pixel off the image is refused.
        page.send(json!({"type": "pick", "x": 48, "y": 0})).await;
        let error = page.next_of("error").await;
        assert!(error["message"].as_str().unwrap().contains("outside"));
    });
}

/// In a scene of mesh instances the walk goes through the top tree over the instances
/// and on into the trees of the instances it reaches.
#[test]
fn a_pick_walks_into_mesh_instances() {
    let server = server_of("teapots", 48, 32, 1000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        page.next_of("tree").await;
        page.send(json!({"type": "pick", "x": 24, "y": 16})).await;
        let walk = page.next_of("walk").await;
        assert_eq!(walk["partial"], false);
        let steps = walk["steps"].as_array().unwrap();
        assert!(
            steps[0]["instance"].is_null(),
            "the walk starts in the top tree"
        );
        let tree = |s: &Value| s["instance"].as_u64();
        assert!(
            steps.iter().any(|s| tree(s) > Some(0)),
            "the walk enters a mesh instance's tree"
        );
        let hit = &walk["hit"];
        let (instance, prim) = (hit["instance"].as_u64(), hit["primitive"].as_u64());
        assert!(steps.iter().any(|s| tree(s) == instance
            && s["leaf"]
                .as_array()
                .is_some_and(|l| l.iter().any(|p| p.as_u64() == prim))));
    });
}

/// The tree's view offers the top tree over the instances; its leaves lead into the
/// trees of the structures they place, a mesh's tree holding all of the mesh.
#[test]
fn the_tree_view_descends_from_the_top_tree_into_a_mesh() {
    let teapot = &canopy_render::load_scene("teapots").unwrap().meshes[0].mesh;
    let triangles = teapot.indices().len();
    let server = server_of("teapots", 32, 24, 1000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        let tree = page.next_of("tree").await;
        assert_eq!(
            (tree["structures"].clone(), tree["top_tree"].clone()),
            (json!(2), json!(true))
        );
        page.send(json!({"type": "node", "tree": "top", "index": null}))
            .await;
        let top = page.next_of("node").await;
        assert_eq!(top["tree"], "top");
        let children = top["children"].as_array().unwrap();
        // 400 teapots and the ground's own structure: every instance below the root once.
        let instances: u64 = children
            .iter()
            .map(|c| c["primitives"].as_u64().unwrap())
            .sum();
        assert_eq!(instances, 401);
        // Descend to a leaf of the top tree: it names the structures it places.
        let mut node = top.clone();
        let placed = loop {
            let children = node["children"].as_array().unwrap().clone();
            if let Some(leaf) = children.iter().find(|c| c["index"].is_null()) {
                break leaf["structures"].clone();
            }
            page.send(json!({"type": "node", "tree": "top", "index": children[0]["index"]}))
                .await;
            node = page.next_of("node").await;
        };
        assert!(placed.as_array().is_some_and(|s| !s.is_empty()), "{placed}");
        page.send(json!({"type": "node", "tree": {"structure": 1}, "index": null}))
            .await;
        let mesh = page.next_of("node").await;
        assert_eq!(mesh["tree"], json!({"structure": 1}));
        let held: u64 = mesh["children"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["primitives"].as_u64().unwrap())
            .sum();
        assert_eq!(held, triangles as u64);
        page.send(json!({"type": "node", "tree": {"structure": 7}, "index": null}))
            .await;
        let error = page.next_of("error").await;
        assert!(
            error["message"]
                .as_str()
                .unwrap()
                .contains("no structure 7"),
            "{error}"
        );
    });
}

#[test]
fn hostile_messages_get_an_error_and_change_nothing() {
    let server = server(32, 24, 1000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        let hostile = [
            json!("not an object").to_string(),
            "{\"type\":".to_string(),
            json!({"type": "format_disk"}).to_string(),
            json!({"type": "settings", "render": {"spp": 0}}).to_string(),
            json!({"type": "settings", "render": {"max_depth": 100000}}).to_string(),
            json!({"type": "settings", "render": {"integrator": "magic"}}).to_string(),
            json!({"type": "settings", "exposure": 1e30}).to_string(),
            json!({"type": "settings", "levels": [5, 2]}).to_string(),
            json!({"type": "settings", "render": {"spp": 4}, "extra": true}).to_string(),
            json!({"type": "settings", "render": {"spp": 4, "extra": true}}).to_string(),
            json!({"type": "settings", "spp": 4}).to_string(),
            json!({"type": "settings", "render": {"bvh": "nope"}}).to_string(),
            json!({"type": "settings", "render": {"bvh": "none"}}).to_string(),
            json!({"type": "settings", "render": {"width": 3}}).to_string(),
            json!({"type": "settings", "render": {"max_leaf_size": 0}}).to_string(),
            json!({"type": "settings", "render": {"size": [8, 8]}}).to_string(),
            json!({"type": "settings", "render": {"device": "gpu"}}).to_string(),
            json!({"type": "settings", "render": {"threads": 1}}).to_string(),
            json!({"type": "rebuild", "builder": "lbvh", "width": 8, "max_leaf_size": 4})
                .to_string(),
            json!({"type": "camera", "look_from": [0, 0, 0], "look_at": [0, 0, 0], "vfov": 40})
                .to_string(),
            json!({"type": "camera", "look_from": [0, 1, 0], "look_at": [0, 0, 0], "vfov": 40})
                .to_string(),
            json!({"type": "camera", "look_from": [1e39, 0, 0], "look_at": [0, 0, 0], "vfov": 40})
                .to_string(),
            json!({"type": "camera", "look_from": [0, 0, 1], "look_at": [0, 0, 0], "vfov": 0})
                .to_string(),
            json!({"type": "pick", "x": -1, "y": 0}).to_string(),
            format!("{{\"type\":\"settings\",\"spp\":{}}}", "9".repeat(100)),
            " ".repeat(100_000),
        ];
        let generation_before = server_generation(&mut page).await;
        for message in &hostile {
            page.send(Value::Null).await; // a valid JSON value that is no command
            page.next_of("error").await;
            page.ws
                .send(Message::Text(message.clone().into()))
                .await
                .unwrap();
            let error = page.next_of("error").await;
            assert!(
                !error["message"].as_str().unwrap().is_empty(),
                "{message:.80} got an empty error"
            );
        }
        page.ws
            .send(Message::Binary(vec![0u8; 64].into()))
            .await
            .unwrap();
        page.next_of("error").await;
        // Nothing changed: the same generation renders on.
        assert_eq!(server_generation(&mut page).await, generation_before);
        // And the session still obeys a good command.
        page.send(json!({"type": "settings", "render": {"spp": 3}}))
            .await;
        page.frame_until(|f| f["target_spp"] == 3).await;
    });
}

/// The generation of the next frame.
async fn server_generation(page: &mut Client) -> u64 {
    page.frame().await.0["generation"].as_u64().unwrap()
}

#[test]
fn a_slow_page_skips_frames_instead_of_queueing_them() {
    // Frames large enough that a page which stops reading fills the socket's buffers
    // after a few of them.
    let server = server(320, 240, 48);
    runtime().block_on(async {
        let mut reader = Client::connect(&server).await;
        // The slow page: a small receive buffer, then it stops reading.
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.set_recv_buffer_size(4096).unwrap();
        let stream = socket.connect(server.addr()).await.unwrap();
        let url = format!("ws://{}/ws?token={}", server.addr(), server.token());
        let (ws, _) = tokio_tungstenite::client_async(url, MaybeTlsStream::Plain(stream))
            .await
            .unwrap();
        let mut slow = Client::after_handshake(ws).await;
        // Until every sample is in, as the page that reads sees it.
        reader.frame_until(|f| f["spp"] == 48).await;
        // The slow page now gets what was in flight, then the latest frame: not 48.
        let mut frames = 0;
        loop {
            let (info, _) = slow.frame().await;
            frames += 1;
            if info["spp"] == 48 {
                break;
            }
        }
        assert!(
            frames < 40,
            "the slow page got {frames} of 49 frames: they queued"
        );
    });
}

#[test]
fn rendering_stops_when_the_last_page_closes() {
    let server = server(48, 32, 1_000_000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        page.frame_until(|f| f["spp"].as_u64() >= Some(2)).await;
        assert!(server.is_rendering());
        page.ws.close(None).await.unwrap();
        wait_until(|| server.clients() == 0).await;
        wait_until(|| !server.is_rendering()).await;
        let made = server.frames_made();
        // No page: nothing renders, however long one waits.
        tokio::time::sleep(Duration::from_millis(300)).await;
        assert_eq!(server.frames_made(), made);
        assert!(!server.is_rendering());
        // A page comes back: rendering resumes.
        let mut again = Client::connect(&server).await;
        again.frame().await;
    });
}

async fn wait_until(condition: impl Fn() -> bool) {
    tokio::time::timeout(PATIENCE, async {
        while !condition() {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    })
    .await
    .expect("the condition did not come true in time");
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("canopy-view-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn save_writes_new_files_and_never_replaces_one() {
    let dir = temp_dir("save");
    let mut scene = canopy_render::load_scene("paper-1").unwrap();
    (
        scene.settings.width,
        scene.settings.height,
        scene.settings.spp,
    ) = (40, 30, 3);
    let options = ViewOptions {
        render: two_threads(),
        save_dir: dir.clone(),
        ..ViewOptions::default()
    };
    let server = ViewServer::start(scene, options).unwrap();
    // A file of the user's where the first name would go.
    std::fs::write(dir.join("paper-1-001.png"), b"the user's").unwrap();
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        page.frame_until(|f| f["spp"] == 3).await;
        for format in ["png", "exr", "png"] {
            page.send(json!({"type": "save", "format": format})).await;
            page.next_of("saved").await;
        }
        page.send(json!({"type": "save", "format": "jpeg"})).await;
        assert!(page.next_of("error").await["message"]
            .as_str()
            .unwrap()
            .contains("png"));
    });
    assert_eq!(
        std::fs::read(dir.join("paper-1-001.png")).unwrap(),
        b"the user's"
    );
    let png = image::open(dir.join("paper-1-002.png")).unwrap();
    assert_eq!((png.width(), png.height()), (40, 30));
    let exr = image::open(dir.join("paper-1-001.exr")).unwrap();
    assert_eq!((exr.width(), exr.height()), (40, 30));
    assert!(dir.join("paper-1-003.png").exists());
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "paper-1-001.exr",
            "paper-1-001.png",
            "paper-1-002.png",
            "paper-1-003.png"
        ],
        "no temporary file left"
    );
    drop(server);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn the_tree_is_descended_node_by_node() {
    let server = server(32, 24, 1000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        let tree = page.next_of("tree").await;
        page.send(json!({"type": "node", "index": null})).await;
        let root = page.next_of("node").await;
        let children = root["children"].as_array().unwrap();
        assert!(children.len() >= 2);
        let prims: u64 = children
            .iter()
            .map(|c| c["primitives"].as_u64().unwrap())
            .sum();
        assert_eq!(prims, tree["primitives"].as_u64().unwrap());
        // The children's shares and the root's own traversal step (cost 1, area 1) make
        // the tree's whole SAH cost.
        let shares: f64 = children
            .iter()
            .map(|c| c["sah_share"].as_f64().unwrap())
            .sum();
        let root_step = 1.0 / tree["sah"].as_f64().unwrap();
        assert!(
            (shares + root_step - 1.0).abs() < 1e-3,
            "{shares} + {root_step}"
        );
        // Down one level, through the child with the most primitives below it.
        let largest = children
            .iter()
            .filter(|c| !c["index"].is_null())
            .max_by_key(|c| c["primitives"].as_u64())
            .unwrap();
        page.send(json!({"type": "node", "index": largest["index"]}))
            .await;
        let below = page.next_of("node").await;
        let below_prims: u64 = below["children"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["primitives"].as_u64().unwrap())
            .sum();
        assert_eq!(below_prims, largest["primitives"].as_u64().unwrap());
        // An index of no inner node is refused.
        page.send(json!({"type": "node", "index": 1u64 << 40}))
            .await;
        page.next_of("error").await;
    });
}

/// A scene file of `spheres` spheres in a row.
fn spheres_scene(spheres: usize) -> String {
    let mut toml = String::from(
        "name = \"row\"\n[camera]\nlook_from = [0, 1, 8]\nlook_at = [0, 0, 0]\nvfov = 40\n\
         [render]\nwidth = 32\nheight = 24\nspp = 100000\nmax_depth = 3\n\
         [materials.grey]\ntype = \"lambertian\"\nalbedo = [0.5, 0.5, 0.5]\n",
    );
    for i in 0..spheres {
        toml += &format!(
            "[[spheres]]\ncenter = [{}, 0, 0]\nradius = 0.4\nmaterial = \"grey\"\n",
            i as f32 - 2.0
        );
    }
    toml
}

#[test]
fn a_changed_scene_file_is_reloaded_with_the_camera_kept() {
    let dir = temp_dir("reload");
    let path = dir.join("row.toml");
    std::fs::write(&path, spheres_scene(2)).unwrap();
    let load = {
        let path = path.to_str().unwrap().to_owned();
        move || canopy_render::load_scene(&path).map_err(|e| e.to_string())
    };
    let options = ViewOptions {
        render: two_threads(),
        save_dir: dir.clone(),
        reload: Some(canopy_view::Reload::new(load.clone())),
        ..ViewOptions::default()
    };
    let server = ViewServer::start(load().unwrap(), options).unwrap();
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        assert_eq!(page.next_of("tree").await["primitives"], 2);
        let mut camera = page.hello["camera"].clone();
        camera["type"] = json!("camera");
        camera["look_from"] = json!([1.0, 2.0, 7.0]);
        page.send(camera.clone()).await;
        page.frame_until(|f| f["generation"].as_u64() >= Some(1))
            .await;

        std::fs::write(&path, spheres_scene(3)).unwrap();
        // The notice and the new tree's report, in either order.
        let news = page.next_of_each(&["reloaded", "tree"]).await;
        assert_eq!(news[0]["primitives"], 3);
        assert_eq!(news[1]["primitives"], 3);
        let second = Client::connect(&server).await;
        assert_eq!(second.hello["camera"]["look_from"], camera["look_from"]);

        // A broken edit: said, and the last good scene renders on.
        std::fs::write(&path, "[camera\nlook_from = ").unwrap();
        let error = page.next_of("error").await;
        let message = error["message"].as_str().unwrap();
        assert!(message.contains("row.toml"), "{message}");
        page.frame().await;

        // Fixed again: reloaded.
        std::fs::write(&path, spheres_scene(4)).unwrap();
        assert_eq!(page.next_of("reloaded").await["primitives"], 4);
    });
    drop(server);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn the_albedo_and_normal_layers_are_shown() {
    let server = server(64, 48, 1000);
    runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        page.send(json!({"type": "settings", "mode": "albedo"}))
            .await;
        let (info, image) = page
            .frame_until(|f| f["mode"] == "albedo" && f["preview"] == false)
            .await;
        assert!(info["spp"].as_u64() >= Some(1));
        // The bottom row sees the ground, lambertian (0.6, 0.12, 0.1): in sRGB about
        // (203, 97, 89), without noise (the albedo of the first surface).
        let mut row: Vec<[u8; 3]> = (0..64).map(|x| image.get_pixel(x, 47).0).collect();
        row.sort_by_key(|p| p[0]);
        let median = row[32];
        for (channel, expected) in [203, 97, 89].into_iter().enumerate() {
            let got = median[channel] as i32;
            assert!(
                (got - expected).abs() <= 8,
                "channel {channel}: {got}, not about {expected}"
            );
        }
        // The normal layer of the same samples: shown at once, no restart.
        let generation = info["generation"].as_u64().unwrap();
        page.send(json!({"type": "settings", "mode": "normal"}))
            .await;
        let (normal, image) = page.frame_until(|f| f["mode"] == "normal").await;
        assert!(normal["generation"].as_u64() > Some(generation));
        assert!(
            normal["spp"].as_u64() >= info["spp"].as_u64(),
            "the samples were kept"
        );
        // The ground's normal points up: (0, 1, 0) shows as (128, 255, 128).
        let mut row: Vec<[u8; 3]> = (0..64).map(|x| image.get_pixel(x, 47).0).collect();
        row.sort_by_key(|p| p[1]);
        let p = row[32];
        assert!(p[1] > 230 && (p[0] as i32 - 128).abs() < 40, "{p:?}");
    });
}

#[test]
fn on_the_gpu_the_view_renders_as_a_gpu_job_does() {
    let dir = temp_dir("gpu");
    let mut scene = canopy_render::load_scene("paper-1").unwrap();
    let s = &mut scene.settings;
    (s.width, s.height, s.spp, s.max_depth) = (40, 30, 3, 4);
    let options = ViewOptions {
        render: RenderOptions {
            device: Some(canopy_job::Device::Gpu),
            ..two_threads()
        },
        save_dir: dir.clone(),
        ..ViewOptions::default()
    };
    let server = match ViewServer::start(scene.clone(), options) {
        Ok(server) => server,
        Err(canopy_view::ViewError::Gpu(e @ canopy_gpu::GpuError::NoAdapter(_))) => {
            eprintln!("SKIPPED: no GPU adapter: {e}");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    let saved = runtime().block_on(async {
        let mut page = Client::connect(&server).await;
        assert_eq!(page.hello["device"], "gpu");
        assert_eq!(page.hello["widths"], json!([2]));
        assert_eq!(page.hello["fast_triangles"], false);
        assert_eq!(page.next_of("tree").await["width"], 2);
        let (done, _) = page
            .frame_until(|f| f["spp"] == 3 && f["preview"] == false)
            .await;
        page.send(json!({"type": "save", "format": "exr"})).await;
        let saved = page.next_of("saved").await["path"]
            .as_str()
            .unwrap()
            .to_string();
        // A wider tree or the CPU's fast triangle test: refused by name.
        for (render, named) in [
            (json!({"width": 4}), "width"),
            (json!({"fast_triangles": true}), "fast_triangles"),
        ] {
            page.send(json!({"type": "settings", "render": render}))
                .await;
            let error = page.next_of("error").await;
            assert!(error["message"].as_str().unwrap().contains(named), "{error}");
        }
        // Another builder is built and rendered through; a camera move renders the new
        // view to its target.
        page.send(json!({"type": "settings", "render": {"bvh": "lbvh"}}))
            .await;
        assert_eq!(page.next_of("tree").await["builder"], "lbvh");
        page.send(json!({"type": "camera", "look_from": [10.0, 3.0, 4.0], "look_at": [0.0, 0.0, 0.0], "vfov": 25.0}))
            .await;
        let generation = done["generation"].as_u64().unwrap();
        let (moved, image) = page
            .frame_until(|f| f["generation"].as_u64().unwrap() > generation + 1 && f["spp"] == 3)
            .await;
        assert_eq!(moved["preview"], false);
        assert!(moved["mrays_per_second"].as_f64().unwrap() > 0.0);
        assert!(image.pixels().any(|p| p.0 != [0, 0, 0]), "black");
        saved
    });
    drop(server);
    // The image the page saved is a GPU render's of that view, bit for bit: the same
    // passes, through an upload kept across views.
    let mut job = canopy_job::RenderJob::new(&scene, "paper-1");
    job.device = canopy_job::Device::Gpu;
    let film = job
        .prepare()
        .unwrap()
        .run(&mut ())
        .unwrap()
        .accumulator
        .film();
    let (width, height, pixels) = canopy_render::output::read_image(saved.as_ref()).unwrap();
    assert_eq!((width, height), (40, 30));
    let expected: Vec<f32> = film.pixels.iter().flat_map(|p| p.to_array()).collect();
    assert_eq!(pixels, expected);
    std::fs::remove_dir_all(dir).unwrap();
}
