//! The HTTP side: the page (built into the binary) and the WebSocket, both behind the
//! session's token; one task per socket sends frames and tree reports as they come and
//! answers the page's commands.

use crate::protocol::{
    BuilderInfo, CameraState, Change, Command, Hello, ServerMessage, ViewSettingsState,
    MAX_SOCKET_MESSAGE_BYTES,
};
use crate::save::save;
use crate::session::Session;
use crate::settings::{current_options, Mode, TreeSettings};
use crate::tree_view::world_node_report;
use crate::walk::{primary_ray, walk};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use canopy_bvh::Builder;
use canopy_render::{Integrator, Sampler};
use serde::Deserialize;
use std::path::PathBuf;
use std::sync::Arc;

/// The page: markup, style and script in one file, no network needed.
const PAGE: &str = include_str!("../page/index.html");

#[derive(Clone)]
pub(crate) struct App {
    pub session: Arc<Session>,
    pub token: Arc<str>,
    /// Where saved images go.
    pub save_dir: Arc<PathBuf>,
}

#[derive(Deserialize)]
pub(crate) struct TokenQuery {
    token: Option<String>,
}

pub(crate) fn router(app: App) -> Router {
    Router::new()
        .route("/", get(page))
        .route("/ws", get(socket))
        .with_state(app)
}

/// Compares in time independent of where the strings differ.
fn token_matches(given: Option<&str>, token: &str) -> bool {
    let Some(given) = given else {
        return false;
    };
    given.len() == token.len()
        && given
            .bytes()
            .zip(token.bytes())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
}

fn refused() -> Response {
    (
        StatusCode::FORBIDDEN,
        "canopy view: this address needs the token printed when the server started\n",
    )
        .into_response()
}

async fn page(State(app): State<App>, Query(q): Query<TokenQuery>) -> Response {
    if !token_matches(q.token.as_deref(), &app.token) {
        return refused();
    }
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        PAGE,
    )
        .into_response()
}

async fn socket(
    State(app): State<App>,
    Query(q): Query<TokenQuery>,
    upgrade: WebSocketUpgrade,
) -> Response {
    if !token_matches(q.token.as_deref(), &app.token) {
        return refused();
    }
    upgrade
        .max_message_size(MAX_SOCKET_MESSAGE_BYTES)
        .max_frame_size(MAX_SOCKET_MESSAGE_BYTES)
        .on_upgrade(move |ws| serve_socket(ws, app))
}

/// A page's connection: counted as a client while it lasts, so that rendering stops
/// when the last one closes.
async fn serve_socket(mut ws: WebSocket, app: App) {
    app.session.client_joined();
    let _ = talk(&mut ws, &app).await;
    app.session.client_left();
}

/// Why a connection ended (the page closed it, or a send failed).
struct Closed;

async fn send(ws: &mut WebSocket, message: &ServerMessage) -> Result<(), Closed> {
    let text = serde_json::to_string(message).expect("server messages serialise");
    ws.send(Message::Text(text.into()))
        .await
        .map_err(|_| Closed)
}

async fn talk(ws: &mut WebSocket, app: &App) -> Result<(), Closed> {
    let session = &app.session;
    send(ws, &hello(session)).await?;
    let mut frames = session.frames.subscribe();
    let mut trees = session.trees.subscribe();
    // Only news from now on: an old reload is no news to a new page.
    let mut notices = session.notices.subscribe();
    // Whatever is there already is news to this page.
    frames.mark_changed();
    trees.mark_changed();
    loop {
        tokio::select! {
            received = ws.recv() => match received {
                Some(Ok(Message::Text(text))) => {
                    if let Some(reply) = command(app, text.as_str()).await {
                        send(ws, &reply).await?;
                    }
                }
                Some(Ok(Message::Binary(_))) => {
                    let message = "binary messages are not commands; send JSON text".into();
                    send(ws, &ServerMessage::Error { message }).await?;
                }
                Some(Ok(Message::Ping(_) | Message::Pong(_))) => {}
                Some(Ok(Message::Close(_))) | Some(Err(_)) | None => return Err(Closed),
            },
            changed = frames.changed() => {
                changed.map_err(|_| Closed)?;
                let frame = frames.borrow_and_update().clone();
                if let Some(frame) = frame {
                    send(ws, &ServerMessage::Frame(frame.info.clone())).await?;
                    ws.send(Message::Binary(frame.jpeg.clone().into()))
                        .await
                        .map_err(|_| Closed)?;
                }
            }
            changed = trees.changed() => {
                changed.map_err(|_| Closed)?;
                let report = trees.borrow_and_update().clone();
                if let Some(report) = report {
                    send(ws, &ServerMessage::Tree((*report).clone())).await?;
                }
            }
            changed = notices.changed() => {
                changed.map_err(|_| Closed)?;
                let notice = notices.borrow_and_update().clone();
                if let Some(notice) = notice {
                    send(ws, &notice).await?;
                }
            }
        }
    }
}

/// Checks and applies a page's command; the reply, if it has one.
async fn command(app: &App, text: &str) -> Option<ServerMessage> {
    let session = &app.session;
    let current = session.control();
    let change = Command::parse(text).and_then(|c| {
        c.apply(
            &current.view,
            &current.tree,
            session.device,
            (session.width, session.height),
        )
    });
    match change {
        Err(message) => Some(ServerMessage::Error { message }),
        Ok(Change::View(view)) => {
            session.set_view(view);
            None
        }
        Ok(Change::Settings { view, tree }) => {
            session.set_settings(view, tree);
            None
        }
        Ok(Change::Pick { x, y }) => {
            let session = session.clone();
            let camera = current.view.camera;
            let explored = tokio::task::spawn_blocking(move || {
                let accel = session
                    .accel
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .clone()?;
                let scene = session.scene.read().unwrap_or_else(|e| e.into_inner());
                let mut at_full_size = scene.settings;
                (at_full_size.width, at_full_size.height) = (session.width, session.height);
                let ray = primary_ray(&camera, &at_full_size, x, y);
                Some(walk(&scene, &accel, &ray))
            })
            .await;
            Some(match explored {
                Ok(Some(w)) => ServerMessage::Walk {
                    x,
                    y,
                    partial: w.partial,
                    steps: w.steps,
                    primitives_tested: w.primitives_tested,
                    hit: w.hit,
                },
                _ => not_built(),
            })
        }
        Ok(Change::Save(format)) => {
            let (session, folder) = (session.clone(), app.save_dir.clone());
            let saved = tokio::task::spawn_blocking(move || {
                let shown = session
                    .shown
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .clone();
                let Some(shown) = shown else {
                    return Err("nothing is shown yet; save again in a moment".to_string());
                };
                let inputs = session
                    .scene
                    .read()
                    .unwrap_or_else(|e| e.into_inner())
                    .inputs
                    .clone();
                save(
                    &shown.film,
                    shown.exposure,
                    format,
                    &folder,
                    &session.name,
                    &inputs,
                )
            })
            .await;
            Some(match saved {
                Ok(Ok(path)) => ServerMessage::Saved {
                    path: path.display().to_string(),
                },
                Ok(Err(message)) => ServerMessage::Error { message },
                Err(_) => ServerMessage::Error {
                    message: "the image could not be saved".into(),
                },
            })
        }
        Ok(Change::Node { tree, index }) => {
            let session = session.clone();
            let costs = current.tree.params().sah;
            let report = tokio::task::spawn_blocking(move || {
                let accel = session
                    .accel
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .clone();
                let accel = accel.ok_or("the tree is not built yet; ask again in a moment")?;
                world_node_report(accel.world(), tree, &costs, index)
            })
            .await;
            Some(match report {
                Ok(Ok(node)) => ServerMessage::Node(node),
                Ok(Err(message)) => ServerMessage::Error { message },
                Err(_) => not_built(),
            })
        }
    }
}

fn not_built() -> ServerMessage {
    ServerMessage::Error {
        message: "the tree is not built yet; ask again in a moment".into(),
    }
}

fn hello(session: &Session) -> ServerMessage {
    let c = session.control();
    let v = &c.view;
    let (widths, fast_triangles) = TreeSettings::offered_on(session.device);
    ServerMessage::Hello(Box::new(Hello {
        scene: session.name.clone(),
        width: session.width,
        height: session.height,
        camera: CameraState::from(&v.camera),
        settings: ViewSettingsState {
            render: current_options(v, &c.tree),
            exposure: v.exposure,
            mode: v.mode,
            levels: v.levels,
        },
        builders: Builder::ALL
            .iter()
            .map(|b| BuilderInfo {
                name: b.name(),
                description: b.description(),
            })
            .collect(),
        device: session.device.name().into(),
        device_name: session.device_name.clone(),
        widths,
        fast_triangles,
        modes: Mode::ALL.to_vec(),
        integrators: Integrator::ALL.iter().map(|i| i.name().into()).collect(),
        samplers: Sampler::ALL.iter().map(|s| s.name().into()).collect(),
    }))
}
