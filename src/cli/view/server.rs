//! The viewer's HTTP and WebSocket server (axum), bound to loopback only: the page and its
//! pinned three.js at `/`, a WebSocket at `/ws` that sends the scene once, then the frame
//! shown whenever it changes (binary, [`super::frames`]), and the outcome of every act
//! (JSON text); it takes the page's messages ([`PageMessage`]).

use super::actions::{Act, InputDesk, Outcome, PageMessage};
use super::assets;
use super::playback::Playback;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use std::path::PathBuf;
use std::sync::Arc;
use tokio::sync::broadcast;

/// Largest message a page may send, in bytes.
const MAX_MESSAGE: usize = 16 * 1024;

/// What the server's handlers share.
pub struct ViewerState {
    /// The display.
    pub playback: Arc<Playback>,
    /// Acts on bodies and the input log.
    pub desk: Arc<InputDesk>,
    /// The scene description sent to every page when it connects (JSON).
    pub scene_json: String,
    /// Outcomes of acts and saves, for every page.
    pub events: broadcast::Sender<String>,
    /// Where "save run" writes the scene and the input log (checked before the run).
    pub save_to: (PathBuf, PathBuf),
    /// The scene as a JSON scene file.
    pub scene_file: String,
}

/// Serves the viewer on `listener` until the process ends.
pub fn serve(listener: std::net::TcpListener, state: Arc<ViewerState>) -> std::io::Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async move {
        listener.set_nonblocking(true)?;
        let listener = tokio::net::TcpListener::from_std(listener)?;
        let app = Router::new()
            .route(
                "/",
                get(|| async { page(assets::INDEX_HTML, "text/html; charset=utf-8") }),
            )
            .route(
                "/app.js",
                get(|| async { page(assets::APP_JS, "text/javascript") }),
            )
            .route(
                "/occlusion.js",
                get(|| async { page(assets::OCCLUSION_JS, "text/javascript") }),
            )
            .route(
                assets::THREE_PATH,
                get(|| async { page(assets::THREE_JS, "text/javascript") }),
            )
            .route(
                assets::ORBIT_PATH,
                get(|| async { page(assets::ORBIT_CONTROLS_JS, "text/javascript") }),
            )
            .route("/ws", get(upgrade))
            .with_state(state);
        axum::serve(listener, app).await
    })
}

fn page(body: &'static str, kind: &'static str) -> Response {
    ([(header::CONTENT_TYPE, kind)], body).into_response()
}

async fn upgrade(ws: WebSocketUpgrade, State(state): State<Arc<ViewerState>>) -> Response {
    ws.max_message_size(MAX_MESSAGE)
        .max_frame_size(MAX_MESSAGE)
        .on_upgrade(move |socket| session(socket, state))
}

/// One page's connection: the scene, then shown frames and outcomes as they come, and the
/// page's messages. A page that reads slowly gets only the latest frame when it is ready.
async fn session(mut socket: WebSocket, state: Arc<ViewerState>) {
    if socket
        .send(Message::Text(state.scene_json.clone().into()))
        .await
        .is_err()
    {
        return;
    }
    let mut frames = state.playback.subscribe();
    frames.mark_changed();
    let mut events = state.events.subscribe();
    loop {
        tokio::select! {
            changed = frames.changed() => {
                if changed.is_err() {
                    return;
                }
                let shown = frames.borrow_and_update().clone();
                if let Some(shown) = shown {
                    if socket.send(Message::Binary(shown.bytes.clone().into())).await.is_err() {
                        return;
                    }
                }
            }
            event = events.recv() => {
                match event {
                    Ok(text) => {
                        if socket.send(Message::Text(text.into())).await.is_err() {
                            return;
                        }
                    }
                    Err(broadcast::error::RecvError::Lagged(_)) => {}
                    Err(broadcast::error::RecvError::Closed) => return,
                }
            }
            incoming = socket.recv() => {
                let Some(Ok(message)) = incoming else { return };
                let reply = match message {
                    Message::Text(text) => handle(&state, text.as_str()),
                    Message::Binary(_) => Err("binary messages are not accepted: send JSON text".to_string()),
                    Message::Ping(_) | Message::Pong(_) => Ok(None),
                    Message::Close(_) => return,
                };
                let reply = match reply {
                    Ok(None) => continue,
                    Ok(Some(text)) => text,
                    Err(reason) => {
                        eprintln!("soda view: rejected a page message: {reason}");
                        serde_json::to_string(&Outcome::Rejected { reason }).expect("JSON")
                    }
                };
                if socket.send(Message::Text(reply.into())).await.is_err() {
                    return;
                }
            }
        }
    }
}

/// Carries out one page message; `Ok(Some(text))` is a reply for that page only.
fn handle(state: &ViewerState, text: &str) -> Result<Option<String>, String> {
    let message: PageMessage = serde_json::from_str(text).map_err(|e| {
        format!(
            "not a viewer message ({e}): expected JSON such as {{\"type\":\"push\",\"id\":3,\"direction\":[1,0,0],\"speed\":2}}"
        )
    })?;
    match message {
        PageMessage::Pause => state.playback.set_paused(true),
        PageMessage::Resume => state.playback.set_paused(false),
        PageMessage::Speed { value } => {
            if !value.is_finite() || value <= 0.0 {
                return Err(format!("speed must be a positive number, got {value}"));
            }
            state.playback.set_speed(value);
        }
        PageMessage::Push {
            id,
            direction,
            speed,
        } => state.desk.queue(Act::Push {
            id,
            direction,
            speed,
        }),
        PageMessage::Spawn { position } => state.desk.queue(Act::Spawn { position }),
        PageMessage::Remove { id } => state.desk.queue(Act::Remove { id }),
        PageMessage::Save => return save(state).map(Some),
    }
    Ok(None)
}

/// Writes the scene and the input log, and says how to replay the run to the shown step.
fn save(state: &ViewerState) -> Result<String, String> {
    let shown = state.playback.shown();
    let (step, hash) = shown.as_ref().map_or((0, 0), |s| (s.step, s.hash));
    let (scene_path, inputs_path) = &state.save_to;
    let log = state.desk.log();
    let inputs = serde_json::to_string_pretty(&log).map_err(|e| e.to_string())?;
    soda::app::atomic::write(scene_path, state.scene_file.as_bytes())
        .map_err(|e| format!("save run: {e:#}"))?;
    soda::app::atomic::write(inputs_path, inputs.as_bytes())
        .map_err(|e| format!("save run: {e:#}"))?;
    let command = format!(
        "soda run --scene {} --inputs {} --steps {step}",
        scene_path.display(),
        inputs_path.display()
    );
    eprintln!(
        "soda view: saved the run at step {step} (hash {hash:016x}, {} inputs): {command}",
        log.inputs.len()
    );
    Ok(serde_json::json!({
        "type": "saved",
        "scene": scene_path.display().to_string(),
        "inputs": inputs_path.display().to_string(),
        "step": step,
        "hash": format!("{hash:016x}"),
        "inputs_logged": log.inputs.len(),
        "command": command,
    })
    .to_string())
}

/// `prefix` with `suffix` appended to its file name.
pub fn with_suffix(prefix: &std::path::Path, suffix: &str) -> PathBuf {
    let mut name = prefix.as_os_str().to_owned();
    name.push(suffix);
    PathBuf::from(name)
}
