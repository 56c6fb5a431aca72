//! The live view's HTTP server (docs/view.md): axum on a current-thread tokio runtime in its
//! own thread, the page's assets ([`super::assets`]) and one websocket, `/ws`, that sends
//! the [`Hub`]'s frames. Every request is hostile: unknown paths are 404, at most
//! [`MAX_CLIENTS`] pages at once (503 beyond), a page's messages are read and ignored (at
//! most 4 KiB each), and a page that does not take a frame within [`SEND_TIMEOUT`] or falls
//! [`super::hub::QUEUE`] frames behind is dropped.

use super::assets::ASSETS;
use super::hub::{Hub, MAX_CLIENTS};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::{header, StatusCode, Uri};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::broadcast::error::RecvError;

/// A frame not taken by a page within this long drops the page.
pub const SEND_TIMEOUT: Duration = Duration::from_secs(2);

/// Binds `addr` (before anything else starts, so a taken port is an error at once) and
/// serves the view from a thread of its own; returns the bound address (port 0: the one the
/// system chose).
pub fn start(addr: SocketAddr, hub: Arc<Hub>) -> anyhow::Result<SocketAddr> {
    let listener = TcpListener::bind(addr)
        .map_err(|e| crate::limits::BadInput(format!("--view-addr {addr}: {e}")))?;
    listener.set_nonblocking(true)?;
    let bound = listener.local_addr()?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .enable_time()
        .build()?;
    std::thread::Builder::new()
        .name("view-http".into())
        .spawn(move || {
            rt.block_on(async move {
                let listener = match tokio::net::TcpListener::from_std(listener) {
                    Ok(l) => l,
                    Err(e) => {
                        estpipe_process::errln!("view: {e}");
                        return;
                    }
                };
                let app = Router::new()
                    .route("/ws", get(ws))
                    .fallback(asset)
                    .with_state(hub);
                if let Err(e) = axum::serve(listener, app).await {
                    estpipe_process::errln!("view: the server stopped: {e}");
                }
            });
        })?;
    Ok(bound)
}

async fn asset(uri: Uri) -> Response {
    match ASSETS.iter().find(|(p, _, _)| *p == uri.path()) {
        Some((_, ty, body)) => ([(header::CONTENT_TYPE, *ty)], *body).into_response(),
        None => (StatusCode::NOT_FOUND, "not found\n").into_response(),
    }
}

async fn ws(State(hub): State<Arc<Hub>>, up: WebSocketUpgrade) -> Response {
    if hub.clients.load(Ordering::Relaxed) >= MAX_CLIENTS {
        return (StatusCode::SERVICE_UNAVAILABLE, "too many viewers\n").into_response();
    }
    up.max_message_size(4096)
        .max_frame_size(4096)
        .on_upgrade(move |s| client(s, hub))
}

/// Counts a connected page while it lives.
struct Connected(Arc<Hub>);

impl Drop for Connected {
    fn drop(&mut self) {
        self.0.clients.fetch_sub(1, Ordering::Relaxed);
    }
}

/// What became of a frame sent to a page.
enum Sent {
    Taken,
    /// The page is gone (closed, reset): not counted as dropped.
    Gone,
    /// Not taken within [`SEND_TIMEOUT`]: the page is dropped.
    Slow,
}

async fn send(socket: &mut WebSocket, frame: &str) -> Sent {
    let msg = Message::Text(frame.to_owned().into());
    match tokio::time::timeout(SEND_TIMEOUT, socket.send(msg)).await {
        Ok(Ok(())) => Sent::Taken,
        Ok(Err(_)) => Sent::Gone,
        Err(_) => Sent::Slow,
    }
}

async fn client(mut socket: WebSocket, hub: Arc<Hub>) {
    hub.clients.fetch_add(1, Ordering::Relaxed);
    let _connected = Connected(Arc::clone(&hub));
    let (past, mut rx) = hub.subscribe();
    let mut sent = send(&mut socket, r#"{"reset":true}"#).await;
    for f in past {
        if !matches!(sent, Sent::Taken) {
            break;
        }
        sent = send(&mut socket, &f).await;
    }
    loop {
        match sent {
            Sent::Taken => {}
            Sent::Gone => return,
            Sent::Slow => {
                hub.drop_slow(&format!(
                    "did not take a frame within {} s",
                    SEND_TIMEOUT.as_secs()
                ));
                return;
            }
        }
        sent = tokio::select! {
            r = rx.recv() => match r {
                Ok(f) => send(&mut socket, &f).await,
                Err(RecvError::Lagged(n)) => {
                    hub.drop_slow(&format!("fell {n} frames behind"));
                    let _ = tokio::time::timeout(SEND_TIMEOUT, socket.send(Message::Close(None))).await;
                    return;
                }
                Err(RecvError::Closed) => return,
            },
            m = socket.recv() => match m {
                None | Some(Err(_)) | Some(Ok(Message::Close(_))) => return,
                Some(Ok(_)) => Sent::Taken,
            },
        };
    }
}
