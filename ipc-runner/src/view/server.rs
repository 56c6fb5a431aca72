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
    // The seat is taken before the upgrade, so that requests sent back to back cannot all
    // pass the count before any of them is connected; a failed upgrade drops it.
    let Some(seat) = Connected::reserve(&hub) else {
        return (StatusCode::SERVICE_UNAVAILABLE, "too many viewers\n").into_response();
    };
    up.max_message_size(4096)
        .max_frame_size(4096)
        .on_upgrade(move |s| client(s, seat))
}

/// Counts a page from its upgrade request for as long as it lives.
struct Connected(Arc<Hub>);

impl Connected {
    /// One of the [`MAX_CLIENTS`] seats, or `None` when all are taken.
    fn reserve(hub: &Arc<Hub>) -> Option<Self> {
        hub.clients
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < MAX_CLIENTS).then_some(n + 1)
            })
            .ok()?;
        Some(Self(Arc::clone(hub)))
    }
}

impl Drop for Connected {
    fn drop(&mut self) {
        self.0.clients.fetch_sub(1, Ordering::AcqRel);
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

async fn client(mut socket: WebSocket, seat: Connected) {
    let hub = Arc::clone(&seat.0);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The 17th page is refused however close together the requests come: a seat is
    /// counted from the request, and given back when the page (or its failed upgrade) ends.
    #[test]
    fn a_seat_is_taken_at_the_request_and_given_back_at_the_end() {
        let hub = Arc::new(Hub::default());
        let seats: Vec<_> = (0..MAX_CLIENTS)
            .map(|i| Connected::reserve(&hub).unwrap_or_else(|| panic!("seat {i}")))
            .collect();
        assert!(Connected::reserve(&hub).is_none());
        drop(seats);
        assert_eq!(hub.clients.load(Ordering::Acquire), 0);
        let threads: Vec<_> = (0..64)
            .map(|_| {
                let hub = Arc::clone(&hub);
                std::thread::spawn(move || Connected::reserve(&hub))
            })
            .collect();
        let got: Vec<_> = threads.into_iter().map(|t| t.join().unwrap()).collect();
        assert_eq!(got.iter().filter(|s| s.is_some()).count(), MAX_CLIENTS);
    }
}
