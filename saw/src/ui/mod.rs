//! `saw ui`: the fig. 11 panel of the SAW display paper as a local web page. An HTTP server on
//! 127.0.0.1 serves one page (compiled into the binary: nothing is fetched at run time) and a
//! WebSocket that bridges it to the link (`bridge`): the page draws what the board answers and
//! sends edits; it never shows its own guess of the board's state.
//!
//! Security: the server controls an RF actuator, so a page from anywhere else must not reach it.
//! It binds to loopback unless `--allow-remote` says otherwise (with a warning), and refuses any
//! request whose Host is not the server's own address (DNS rebinding) or whose Origin is not the
//! server's own page (cross-site requests and WebSockets).
//!
//! The port: a missing or busy port is said on the terminal at start (the page says it too once
//! one is open), and the port is held only while a page is connected (`bridge`).

mod bridge;
pub mod experiment;

use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use tokio::sync::broadcast;

pub use bridge::Command as BridgeCommand;

/// The page, compiled in.
const PAGE: &str = include_str!("page.html");

/// How the panel is started.
#[derive(Clone, Debug)]
pub struct UiOptions {
    /// The board's serial port.
    pub port: PathBuf,
    /// Where the HTTP server listens.
    pub listen: SocketAddr,
    /// Whether a non-loopback `listen` is allowed.
    pub allow_remote: bool,
    /// How long to wait for each answer from the board.
    pub timeout: Duration,
    /// Stream decimation: a record every N samples.
    pub every: u16,
}

/// What every new page gets first: the link's state, the scene, the stream's rate, the counters
/// (JSON messages).
#[derive(Default)]
pub(crate) struct Snapshot {
    pub link: Option<String>,
    pub scene: Option<String>,
    pub stream: Option<String>,
    pub counters: Option<String>,
}

#[derive(Clone)]
struct App {
    out: broadcast::Sender<String>,
    snapshot: Arc<Mutex<Snapshot>>,
    commands: std::sync::mpsc::Sender<(u64, BridgeCommand)>,
    /// Host header values that name this server.
    hosts: Arc<Vec<String>>,
    /// Pages connected now: the bridge holds the port only while there is one.
    pages: Arc<AtomicUsize>,
}

/// Counts a page while its socket is open (also when the session ends by an error).
struct PageOpen(Arc<AtomicUsize>);

impl PageOpen {
    fn new(pages: &Arc<AtomicUsize>) -> Self {
        pages.fetch_add(1, Ordering::Relaxed);
        Self(pages.clone())
    }
}

impl Drop for PageOpen {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// A running panel: its address; dropping the handle leaves it running until `stop`.
pub struct UiHandle {
    /// The address the server listens on.
    pub addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
    /// The bridge thread: it owns the port, so `stop` waits for it to let go.
    bridge: Option<std::thread::JoinHandle<()>>,
    bridge_stop: Arc<std::sync::atomic::AtomicBool>,
}

impl UiHandle {
    /// Stops the server and the bridge (the port is released).
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.bridge_stop
            .store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        // The port is closed (and its lock dropped) only when the bridge's loop sees the flag.
        if let Some(t) = self.bridge.take() {
            let _ = t.join();
        }
    }

    /// Blocks until the server ends.
    pub fn wait(mut self) {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for UiHandle {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Checks the listen address against `--allow-remote`: one line naming the flag when refused.
pub fn check_listen(listen: SocketAddr, allow_remote: bool) -> Result<Option<String>, String> {
    if listen.ip().is_loopback() {
        return Ok(None);
    }
    if !allow_remote {
        return Err(format!(
            "--listen {listen}: not a loopback address; the panel drives an RF actuator, so it listens on 127.0.0.1 unless --allow-remote is given"
        ));
    }
    Ok(Some(format!(
        "warning: --listen {listen} with --allow-remote: anyone who can reach this address can drive the display"
    )))
}

/// The Host header values that name a server at `addr`.
fn host_names(addr: SocketAddr) -> Vec<String> {
    let port = addr.port();
    let mut v = vec![
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        format!("[::1]:{port}"),
    ];
    match addr.ip() {
        IpAddr::V4(ip) if !ip.is_loopback() && !ip.is_unspecified() => {
            v.push(format!("{ip}:{port}"))
        }
        IpAddr::V6(ip) if !ip.is_loopback() && !ip.is_unspecified() => {
            v.push(format!("[{ip}]:{port}"))
        }
        _ => {}
    }
    v
}

/// Refuses a request whose Host is not this server or whose Origin is not this server's page.
async fn guard(State(app): State<App>, req: Request, next: Next) -> Response {
    match allowed(&app.hosts, req.headers()) {
        Ok(()) => next.run(req).await,
        Err(why) => (StatusCode::FORBIDDEN, why).into_response(),
    }
}

/// The Host/Origin rule: Host must be one of `hosts`; Origin, when sent, must be `http://` + one
/// of them.
pub fn allowed(hosts: &[String], headers: &HeaderMap) -> Result<(), String> {
    let host = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .unwrap_or("");
    if !hosts.iter().any(|h| h == host) {
        return Err(format!(
            "refused: Host `{host}` is not this panel's address ({}); the panel answers only its own page",
            hosts[0]
        ));
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let origin = origin.to_str().unwrap_or("");
        if !hosts.iter().any(|h| origin == format!("http://{h}")) {
            return Err(format!(
                "refused: Origin `{origin}` is not this panel's page (http://{}); another site may not drive the display",
                hosts[0]
            ));
        }
    }
    Ok(())
}

async fn page() -> impl IntoResponse {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        Html(PAGE),
    )
}

async fn ws(State(app): State<App>, upgrade: WebSocketUpgrade) -> Response {
    upgrade.on_upgrade(move |socket| session(app, socket))
}

/// One page's WebSocket: the snapshot, then everything the bridge publishes; commands in.
async fn session(app: App, mut socket: WebSocket) {
    let _open = PageOpen::new(&app.pages);
    let mut rx = app.out.subscribe();
    let first: Vec<String> = {
        let s = app.snapshot.lock().unwrap_or_else(|e| e.into_inner());
        [&s.link, &s.scene, &s.stream, &s.counters]
            .into_iter()
            .flatten()
            .cloned()
            .collect()
    };
    for m in first {
        if socket.send(Message::Text(m.into())).await.is_err() {
            return;
        }
    }
    loop {
        tokio::select! {
            out = rx.recv() => match out {
                Ok(m) => {
                    if socket.send(Message::Text(m.into())).await.is_err() {
                        return;
                    }
                }
                // A slow page misses messages rather than slowing the bridge.
                Err(broadcast::error::RecvError::Lagged(_)) => {}
                Err(_) => return,
            },
            msg = socket.recv() => match msg {
                Some(Ok(Message::Text(t))) => {
                    let reply = match bridge::parse_command(&t) {
                        Ok((id, c)) => {
                            let _ = app.commands.send((id, c));
                            None
                        }
                        Err((id, why)) => Some(serde_json::json!({"t": "answer", "id": id, "ok": false, "text": why}).to_string()),
                    };
                    if let Some(r) = reply {
                        if socket.send(Message::Text(r.into())).await.is_err() {
                            return;
                        }
                    }
                }
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => return,
                Some(Ok(_)) => {}
            },
        }
    }
}

/// An HTTP server on its own thread (a current-thread tokio runtime): the panel's and the
/// participant's.
pub(crate) struct Served {
    /// Send (or drop) to stop it gracefully.
    pub(crate) stop: tokio::sync::oneshot::Sender<()>,
    /// Receives once the server has stopped (to wait with a time limit).
    pub(crate) stopped: std::sync::mpsc::Receiver<()>,
    /// The thread.
    pub(crate) thread: std::thread::JoinHandle<()>,
}

/// Serves `router` on `listener` from a thread named `name`; a failure to start the runtime or
/// to take the listener is said on stderr as `runtime_error: …` or `flag: …`.
pub(crate) fn serve_thread(
    name: &str,
    listener: std::net::TcpListener,
    router: Router,
    runtime_error: &'static str,
    flag: &'static str,
) -> Result<Served, String> {
    let (stop, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let (stopped_tx, stopped) = std::sync::mpsc::channel();
    let thread = std::thread::Builder::new()
        .name(name.into())
        .spawn(move || {
            let rt = match tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
            {
                Ok(rt) => rt,
                Err(e) => {
                    eprintln!("error: {runtime_error}: {e}");
                    return;
                }
            };
            rt.block_on(async move {
                let listener = match tokio::net::TcpListener::from_std(listener) {
                    Ok(l) => l,
                    Err(e) => {
                        eprintln!("error: {flag}: {e}");
                        return;
                    }
                };
                let _ = axum::serve(listener, router)
                    .with_graceful_shutdown(async {
                        let _ = stop_rx.await;
                    })
                    .await;
            });
            let _ = stopped_tx.send(());
        })
        .map_err(|e| format!("the panel's server thread did not start: {e}"))?;
    Ok(Served {
        stop,
        stopped,
        thread,
    })
}

/// Starts the panel: the bridge thread on the port and the HTTP server on `opts.listen` (port 0:
/// any free one). Returns once the server listens.
pub fn start(opts: UiOptions) -> Result<UiHandle, String> {
    check_listen(opts.listen, opts.allow_remote)?;
    let std_listener = std::net::TcpListener::bind(opts.listen)
        .map_err(|e| format!("--listen {}: {e}", opts.listen))?;
    std_listener
        .set_nonblocking(true)
        .map_err(|e| format!("--listen {}: {e}", opts.listen))?;
    let addr = std_listener
        .local_addr()
        .map_err(|e| format!("--listen {}: {e}", opts.listen))?;
    let (out, _) = broadcast::channel(256);
    let snapshot = Arc::new(Mutex::new(Snapshot::default()));
    let (commands, commands_rx) = std::sync::mpsc::channel();
    let bridge_stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    // The port is tried once now, so that a missing or busy one is said on the terminal at
    // start; then it is let go until a page connects.
    let said = crate::port::open(&opts.port).err();
    if let Some(why) = &said {
        eprintln!(
            "saw ui: {why}; the panel opens it when a page connects, and tries again every {} s while one is open",
            bridge::RETRY.as_secs_f64()
        );
    }
    let pages = Arc::new(AtomicUsize::new(0));
    let bridge = bridge::spawn(
        opts.clone(),
        out.clone(),
        snapshot.clone(),
        commands_rx,
        bridge_stop.clone(),
        pages.clone(),
        said,
    );
    let app = App {
        out,
        snapshot,
        commands,
        hosts: Arc::new(host_names(addr)),
        pages,
    };
    let router = Router::new()
        .route("/", get(page))
        .route("/ws", get(ws))
        .layer(middleware::from_fn_with_state(app.clone(), guard))
        .with_state(app);
    let served = serve_thread(
        "saw-ui-http",
        std_listener,
        router,
        "the panel's runtime did not start",
        "--listen",
    )?;
    Ok(UiHandle {
        addr,
        stop: Some(served.stop),
        thread: Some(served.thread),
        bridge,
        bridge_stop,
    })
}
