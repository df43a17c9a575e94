//! The participant's panel of `saw experiment run --panel`: a `Participant` that asks on web
//! pages instead of (and as well as) the terminal. `/participant` shows the participant what to
//! do now in large type and takes the response with one large button per word (a tablet on the
//! lab network, or a second screen); `/experimenter` shows the session's progress, what is
//! presented now and the last responses, and confirms objects handed over. The session itself
//! (order, board, log) stays in `crate::experiment::run`: this only asks and waits.
//!
//! Security: whoever reaches the panel answers for the participant, so every request and every
//! WebSocket upgrade must carry the run's token (128 bits from the operating system's CSPRNG,
//! printed in the URLs; `?token=` or the cookie the first tokened request sets, as Jupyter does),
//! on loopback too (another user of the machine must not answer either). A request whose
//! `Origin` is not the panel's own page is refused (another site's script in the experimenter's
//! browser), and a non-loopback address needs `--allow-remote`.
//!
//! Answers come from a page (`POST /respond`, checked against the trial's values: a value out of
//! range is refused with a sentence and nothing is recorded) or from the terminal; the first
//! answer to a prompt counts, later ones are refused.

use std::io::{BufRead, Write};
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use axum::body::Bytes;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode, Uri};
use axum::middleware::{self, Next};
use axum::response::{Html, IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use axum::Router;
use saw_experiment::protocol::Protocol;
use saw_experiment::runner::{Runner, Trial};
use saw_experiment::session::{self, Shown};
use serde_json::{json, Value};
use tokio::sync::watch;

use crate::experiment::Participant;
use crate::Failure;

/// Both views' page, compiled in (nothing is fetched at run time).
const PAGE: &str = include_str!("participant.html");
/// The responses the experimenter's view lists.
const HISTORY: usize = 10;
/// The largest request body: an answer is a few dozen bytes.
const MAX_BODY: usize = 4096;
/// How long the last state is given to reach open pages when the session ends.
const FAREWELL: Duration = Duration::from_millis(300);

/// How the panel is started.
pub struct PanelOptions {
    /// Where it listens (port 0: any free one).
    pub listen: SocketAddr,
    /// Whether a non-loopback `listen` is allowed.
    pub allow_remote: bool,
    /// `--json`: the URLs also go to stdout as a JSON line.
    pub json: bool,
    /// The protocol run (the views' plan: trials, blocks, the exploration time).
    pub protocol: Protocol,
    /// The subject's id.
    pub subject: String,
    /// `--subject-index`, as given.
    pub subject_index: Option<u32>,
    /// The sessions' directory (the log the views' plan is read from).
    pub out: PathBuf,
}

/// Checks `--panel` against `--allow-remote`: one sentence naming the flag when refused, a
/// warning when allowed off loopback.
pub fn check_listen(listen: SocketAddr, allow_remote: bool) -> Result<Option<String>, String> {
    if listen.ip().is_loopback() {
        return Ok(None);
    }
    if !allow_remote {
        return Err(format!(
            "--panel {listen}: not a loopback address; the participant's panel listens on loopback (127.0.0.1) unless --allow-remote is given"
        ));
    }
    Ok(Some(format!(
        "warning: --panel {listen} with --allow-remote: anyone on this network who has the printed URL (its token) can answer for the participant"
    )))
}

/// What is asked (or shown) now.
#[derive(Clone, Debug)]
enum Prompt {
    Starting,
    Instructions {
        text: String,
    },
    Rest {
        done: u32,
        planned: u32,
    },
    HandOver {
        interval: usize,
        stimulus: String,
        prompt: String,
    },
    Explore {
        interval: usize,
        of: usize,
    },
    Question {
        trial: Trial,
    },
    Over {
        finished: bool,
    },
}

impl Prompt {
    /// Whether it waits for a Continue (or Enter).
    fn continues(&self) -> bool {
        matches!(
            self,
            Prompt::Instructions { .. } | Prompt::Rest { .. } | Prompt::HandOver { .. }
        )
    }
}

/// Where an answer came from.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Source {
    Page,
    Terminal,
}

impl Source {
    fn name(self) -> &'static str {
        match self {
            Source::Page => "page",
            Source::Terminal => "terminal",
        }
    }
}

/// An answer to the prompt it was given for.
#[derive(Clone, Copy, Debug)]
enum Answer {
    Continue(Source),
    Value(i32, Source),
}

/// What a page or the terminal offers.
enum Offer {
    /// Continue prompt `seq`.
    Continue { seq: u64 },
    /// Answer trial `trial` (0-based, as in the CSV) with `value`.
    Respond { trial: u32, value: i32 },
}

/// A response, as the experimenter's view lists it.
struct Line {
    number: u32,
    block: String,
    stimuli: Vec<String>,
    value: i32,
    word: String,
    from: Source,
    ms: f64,
}

struct Inner {
    /// The prompt's number: every prompt a new one, so a stale click does not answer the next.
    seq: u64,
    prompt: Prompt,
    /// The answer to prompt `seq`, once given.
    answer: Option<(u64, Answer)>,
    /// The runner's order replayed alongside the session (from its log), for the views' "what
    /// comes now"; None when it cannot be (the views then say less).
    mirror: Option<Runner>,
    mirror_tried: bool,
    planned: u32,
    at_most: bool,
    experiment: String,
    subject: String,
    explore_s: f64,
    history: Vec<Line>,
    /// Pages open now: participant, experimenter.
    pages: [usize; 2],
}

impl Inner {
    fn answered(&self) -> bool {
        self.answer.as_ref().is_some_and(|(s, _)| *s == self.seq)
    }

    /// The trial presented or asked now.
    fn current(&self) -> Option<&Trial> {
        match &self.prompt {
            Prompt::Question { trial } => Some(trial),
            _ => self.mirror.as_ref().and_then(|m| m.next_trial()),
        }
    }
}

struct Shared {
    inner: Mutex<Inner>,
    answered: Condvar,
    /// Each view as JSON, and whether it is the last (the session is over).
    participant: watch::Sender<(String, bool)>,
    experimenter: watch::Sender<(String, bool)>,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Sends both views of `g` to the pages (and to pages that connect later).
    fn publish(&self, g: &Inner) {
        let last = matches!(g.prompt, Prompt::Over { .. });
        self.participant
            .send_replace((participant_view(g).to_string(), last));
        self.experimenter
            .send_replace((experimenter_view(g).to_string(), last));
    }

    /// Shows `prompt`: its number.
    fn ask(&self, prompt: Prompt) -> u64 {
        let mut g = self.lock();
        g.seq += 1;
        g.prompt = prompt;
        g.answer = None;
        self.publish(&g);
        g.seq
    }

    /// Blocks until prompt `seq` is answered.
    fn wait(&self, seq: u64) -> Answer {
        let mut g = self.lock();
        loop {
            if let Some((s, a)) = g.answer {
                if s == seq {
                    return a;
                }
            }
            g = self.answered.wait(g).unwrap_or_else(|e| e.into_inner());
        }
    }

    /// Takes an answer if it answers what is asked now: a sentence saying what was recorded,
    /// or the status and sentence of a refusal (nothing recorded).
    fn offer(&self, offer: Offer, from: Source) -> Result<String, (StatusCode, String)> {
        let mut g = self.lock();
        let seq = g.seq;
        let taken = g.answered();
        let said = match (&g.prompt, offer) {
            (Prompt::Question { trial }, Offer::Respond { trial: t, value }) => {
                if t != trial.number {
                    return Err((
                        StatusCode::CONFLICT,
                        format!(
                            "trial {t}: not the trial asked now (trial {}); nothing recorded",
                            trial.number
                        ),
                    ));
                }
                if taken {
                    return Err((
                        StatusCode::CONFLICT,
                        format!(
                            "trial {t} is answered already; the first answer counts, nothing recorded"
                        ),
                    ));
                }
                let Some(k) = trial.values.iter().position(|v| *v == value) else {
                    return Err((
                        StatusCode::BAD_REQUEST,
                        format!(
                            "value {value}: not an answer to trial {t}; it is one of {}; nothing recorded",
                            list(&trial.values)
                        ),
                    ));
                };
                let said = format!("trial {t}: {value} ({})", trial.words[k]);
                g.answer = Some((seq, Answer::Value(value, from)));
                said
            }
            (p, Offer::Continue { seq: s }) if p.continues() => {
                if s != seq || taken {
                    return Err((
                        StatusCode::CONFLICT,
                        format!("step {s}: over already (step {seq} is shown now); nothing done"),
                    ));
                }
                g.answer = Some((seq, Answer::Continue(from)));
                "continued".into()
            }
            (p, Offer::Respond { trial, .. }) => {
                return Err((
                    StatusCode::CONFLICT,
                    format!(
                        "trial {trial}: no question is open now ({}); nothing recorded",
                        phase(p)
                    ),
                ))
            }
            (p, Offer::Continue { seq: s }) => {
                return Err((
                    StatusCode::CONFLICT,
                    format!(
                        "step {s}: nothing waits for Continue now ({}); nothing done",
                        phase(p)
                    ),
                ))
            }
        };
        self.answered.notify_all();
        self.publish(&g);
        Ok(said)
    }

    /// A line typed at the terminal: Enter continues, a number answers.
    fn typed(&self, line: &str) {
        let offer = {
            let g = self.lock();
            match &g.prompt {
                Prompt::Question { trial } => match line.parse::<i32>() {
                    Ok(value) => Offer::Respond {
                        trial: trial.number,
                        value,
                    },
                    Err(_) => {
                        eprintln!(
                            "{line:?} is not an answer here: type one of {}",
                            list(&trial.values)
                        );
                        return;
                    }
                },
                p if p.continues() => Offer::Continue { seq: g.seq },
                p => {
                    eprintln!("nothing is asked now ({}); {line:?} dropped", phase(p));
                    return;
                }
            }
        };
        if let Err((_, why)) = self.offer(offer, Source::Terminal) {
            eprintln!("{why}");
        }
    }
}

fn list(values: &[i32]) -> String {
    values
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

fn phase(p: &Prompt) -> &'static str {
    match p {
        Prompt::Starting => "starting",
        Prompt::Instructions { .. } => "instructions",
        Prompt::Rest { .. } => "rest",
        Prompt::HandOver { .. } => "hand_over",
        Prompt::Explore { .. } => "explore",
        Prompt::Question { .. } => "question",
        Prompt::Over { .. } => "over",
    }
}

/// "Explore the first surface now."
fn explore_sentence(interval: usize, of: usize) -> String {
    const ORDINAL: [&str; 4] = ["first", "second", "third", "fourth"];
    if of == 1 {
        "Explore the surface now.".into()
    } else if of <= ORDINAL.len() {
        format!("Explore the {} surface now.", ORDINAL[interval.min(3)])
    } else {
        format!("Explore surface {} of {of} now.", interval + 1)
    }
}

fn question_json(t: &Trial, open: bool) -> Value {
    json!({
        "trial": t.number,
        "text": t.question,
        "buttons": t.values.iter().zip(&t.words).map(|(v, w)| json!({"value": v, "word": w})).collect::<Vec<_>>(),
        "open": open,
    })
}

/// What the participant sees: no stimulus names, levels or targets (nothing that could bias the
/// answer is sent to the participant's page).
fn participant_view(g: &Inner) -> Value {
    let answered = g.answered();
    let mut v = json!({"view": "participant", "seq": g.seq, "phase": phase(&g.prompt)});
    let (text, button) = match &g.prompt {
        Prompt::Starting => ("Please wait: the session is about to begin.".into(), None),
        Prompt::Instructions { text } => (
            if text.trim().is_empty() {
                "Press Begin when you are ready.".into()
            } else {
                text.clone()
            },
            Some("Begin"),
        ),
        Prompt::Rest { done, planned } => (
            format!("A break: {done} of {planned} trials done. Continue when you are ready."),
            Some("Continue"),
        ),
        Prompt::HandOver { .. } => (
            "Please wait: the experimenter is placing the next surface.".into(),
            None,
        ),
        Prompt::Explore { interval, of } => {
            v["explore_s"] = json!(g.explore_s);
            // The question to come, its buttons shown but closed until the explorations end.
            if let Some(t) = g.current() {
                v["question"] = question_json(t, false);
            }
            (explore_sentence(*interval, *of), None)
        }
        Prompt::Question { trial } => {
            v["question"] = question_json(trial, !answered);
            (String::new(), None)
        }
        Prompt::Over { finished: true } => ("The session is over. Thank you!".into(), None),
        Prompt::Over { finished: false } => (
            "The session has stopped. Please wait for the experimenter.".into(),
            None,
        ),
    };
    v["text"] = json!(text);
    if answered {
        v["phase"] = json!("answered");
        v["text"] = json!(if matches!(g.prompt, Prompt::Question { .. }) {
            "Thank you."
        } else {
            "Please wait."
        });
        v["question"] = Value::Null;
    } else if let Some(b) = button {
        v["button"] = json!(b);
    }
    v
}

/// What the experimenter sees: the progress, what is presented now, the last responses.
fn experimenter_view(g: &Inner) -> Value {
    let current = g.current();
    let answered = g.answered();
    let n = current.map(|t| t.number + 1);
    let trial_name = n.map_or("the next trial".to_string(), |n| format!("trial {n}"));
    let now = match &g.prompt {
        Prompt::Starting => "starting".to_string(),
        Prompt::Instructions { .. } => {
            "the instructions are shown: the participant's Begin (or Enter at the terminal) starts the session".into()
        }
        Prompt::Rest { done, planned } => format!(
            "a break ({done} of {planned} done) before {trial_name}: the participant's Continue goes on"
        ),
        Prompt::HandOver {
            interval,
            stimulus,
            prompt,
        } => format!(
            "{trial_name}, interval {}: hand over {stimulus}: {prompt}",
            interval + 1
        ),
        Prompt::Explore { interval, of } => {
            let what = current
                .and_then(|t| t.intervals.get(*interval))
                .map_or(String::new(), |i| format!(": {}", i.stimulus));
            format!(
                "{trial_name}: the participant explores interval {} of {of}{what}",
                interval + 1
            )
        }
        Prompt::Question { .. } => format!("{trial_name}: waiting for the response"),
        Prompt::Over { finished: true } => "the session is over".into(),
        Prompt::Over { finished: false } => "the session stopped before its end".into(),
    };
    let now = if answered {
        format!("{now} — answered")
    } else {
        now
    };
    let history: Vec<Value> = g
        .history
        .iter()
        .rev()
        .take(HISTORY)
        .map(|l| {
            json!({
                "trial": l.number + 1,
                "block": l.block,
                "stimuli": l.stimuli,
                "value": l.value,
                "word": l.word,
                "from": l.from.name(),
                "ms": (l.ms).round(),
            })
        })
        .collect();
    let mut v = json!({
        "view": "experimenter",
        "seq": g.seq,
        "phase": if answered { "answered" } else { phase(&g.prompt) },
        "experiment": g.experiment,
        "subject": g.subject,
        "planned": g.planned,
        "at_most": g.at_most,
        "now": now,
        "answered_this_run": g.history.len(),
        "history": history,
        "pages": {"participant": g.pages[0], "experimenter": g.pages[1]},
        "continue": g.prompt.continues() && !answered,
    });
    if let Some(t) = current {
        v["trial"] = json!({
            "n": t.number + 1,
            "block": t.block,
            "block_number": t.block_number + 1,
            "design": t.design,
            "stimuli": t.intervals.iter().map(|i| i.stimulus.clone()).collect::<Vec<_>>(),
            "track": t.track,
            "level": t.level,
        });
    }
    if let Prompt::Explore { interval, .. } = &g.prompt {
        v["interval"] = json!(interval);
    }
    if let Prompt::HandOver {
        interval,
        stimulus,
        prompt,
    } = &g.prompt
    {
        v["interval"] = json!(interval);
        v["hand_over"] = json!({"stimulus": stimulus, "prompt": prompt});
    }
    v
}

/// The panel: a running server and the session's side of it.
pub struct Panel {
    shared: Arc<Shared>,
    protocol: Protocol,
    subject: String,
    subject_index: Option<u32>,
    out: PathBuf,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    stopped: Option<std::sync::mpsc::Receiver<()>>,
    /// The participant's page, with its token.
    pub participant_url: String,
    /// The experimenter's page, with its token.
    pub experimenter_url: String,
}

#[derive(Clone)]
struct App {
    shared: Arc<Shared>,
    token: Arc<str>,
    /// The cookie's name: one per port, since browsers keep cookies per host, not per port.
    cookie: Arc<str>,
}

/// 128 bits from the operating system's CSPRNG, as 32 hex digits.
fn new_token() -> Result<String, String> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b).map_err(|e| {
        format!("the operating system's random source failed ({e}); the panel's token needs it")
    })?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// Equal strings, compared in a time that does not depend on where they differ.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

/// `token=` of a query string (the first, if several).
fn query_token(query: Option<&str>) -> Option<&str> {
    query?.split('&').find_map(|p| p.strip_prefix("token="))
}

/// The panel's cookie, if the request carries it.
fn cookie_token<'a>(headers: &'a HeaderMap, name: &str) -> Option<&'a str> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|h| h.to_str().ok())
        .flat_map(|h| h.split(';'))
        .find_map(|c| c.trim().strip_prefix(name)?.strip_prefix('='))
}

/// The Origin rule: when a request names its origin, it must be this panel's own page, the
/// origin of the Host it was sent to.
fn origin_allowed(headers: &HeaderMap) -> Result<(), String> {
    let Some(origin) = headers.get(header::ORIGIN) else {
        return Ok(());
    };
    let origin = origin.to_str().unwrap_or("");
    let host = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .unwrap_or("");
    if !host.is_empty() && origin == format!("http://{host}") {
        return Ok(());
    }
    let shown: String = origin
        .chars()
        .filter(|c| !c.is_control())
        .take(100)
        .collect();
    Err(format!(
        "refused: Origin `{shown}` is not this panel's own page (http://{host}); another site may not answer for the participant"
    ))
}

fn forbidden(why: String) -> Response {
    (
        StatusCode::FORBIDDEN,
        [(header::CACHE_CONTROL, "no-store")],
        why,
    )
        .into_response()
}

/// Every request passes here before it is routed (unknown paths too): the token, then the
/// Origin. A request in the wrong is answered 403 with one sentence and nothing else.
async fn guard(State(app): State<App>, req: Request, next: Next) -> Response {
    let query = query_token(req.uri().query());
    let cookie = cookie_token(req.headers(), &app.cookie);
    // A token in the URL decides (a stale cookie from an earlier run is then replaced).
    let ok = match (query, cookie) {
        (Some(t), _) | (None, Some(t)) => same(t, &app.token),
        (None, None) => false,
    };
    if !ok {
        return forbidden(if query.is_some() || cookie.is_some() {
            "refused: the token is not this run's; open the URL `saw experiment run` printed".into()
        } else {
            "refused: this panel needs the run's token (the ?token=… of the URL `saw experiment run` printed); nothing is served without it".into()
        });
    }
    if let Err(why) = origin_allowed(req.headers()) {
        return forbidden(why);
    }
    let set_cookie = query.is_some();
    let mut resp = next.run(req).await;
    let h = resp.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    // The token is in the page's URL: no Referer carries it anywhere, no other site frames it.
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    if set_cookie {
        if let Ok(c) = HeaderValue::from_str(&format!(
            "{}={}; Path=/; HttpOnly; SameSite=Strict",
            app.cookie, app.token
        )) {
            h.append(header::SET_COOKIE, c);
        }
    }
    resp
}

async fn page() -> impl IntoResponse {
    (
        [(header::CONTENT_TYPE, "text/html; charset=utf-8")],
        Html(PAGE),
    )
}

/// `/` goes to the participant's page, its query (the token) kept.
async fn root(uri: Uri) -> Redirect {
    Redirect::to(&match uri.query() {
        Some(q) => format!("/participant?{q}"),
        None => "/participant".into(),
    })
}

/// The body's JSON object, or a 400 naming the shape expected.
fn body_json(body: &[u8], shape: &str) -> Result<Value, (StatusCode, String)> {
    serde_json::from_slice::<Value>(body)
        .ok()
        .filter(Value::is_object)
        .ok_or_else(|| {
            (
                StatusCode::BAD_REQUEST,
                format!("the body is not JSON of the form {shape}; nothing recorded"),
            )
        })
}

fn answer(r: Result<String, (StatusCode, String)>) -> Response {
    match r {
        Ok(s) => (StatusCode::OK, s).into_response(),
        Err((code, s)) => (code, s).into_response(),
    }
}

async fn respond(State(app): State<App>, body: Bytes) -> Response {
    const SHAPE: &str = r#"{"trial": N, "value": V}"#;
    answer((|| {
        let v = body_json(&body, SHAPE)?;
        let trial = v["trial"].as_u64().and_then(|t| u32::try_from(t).ok());
        let value = v["value"].as_i64().and_then(|x| i32::try_from(x).ok());
        let (Some(trial), Some(value)) = (trial, value) else {
            return Err((
                StatusCode::BAD_REQUEST,
                format!(
                    "`trial` = {}, `value` = {}: both must be whole numbers (the body is {SHAPE}); nothing recorded",
                    v["trial"], v["value"]
                ),
            ));
        };
        app.shared
            .offer(Offer::Respond { trial, value }, Source::Page)
    })())
}

async fn continue_(State(app): State<App>, body: Bytes) -> Response {
    const SHAPE: &str = r#"{"seq": N}"#;
    answer((|| {
        let v = body_json(&body, SHAPE)?;
        let Some(seq) = v["seq"].as_u64() else {
            return Err((
                StatusCode::BAD_REQUEST,
                format!(
                    "`seq` = {}: must be a whole number (the body is {SHAPE}); nothing done",
                    v["seq"]
                ),
            ));
        };
        app.shared.offer(Offer::Continue { seq }, Source::Page)
    })())
}

#[derive(Clone, Copy)]
enum View {
    Participant,
    Experimenter,
}

/// Counts a page while its socket is open (the experimenter sees whether the participant's is).
struct PageOpen(Arc<Shared>, usize);

impl PageOpen {
    fn new(shared: &Arc<Shared>, k: usize) -> Self {
        let mut g = shared.lock();
        g.pages[k] += 1;
        shared.publish(&g);
        Self(shared.clone(), k)
    }
}

impl Drop for PageOpen {
    fn drop(&mut self) {
        let mut g = self.0.lock();
        g.pages[self.1] -= 1;
        self.0.publish(&g);
    }
}

async fn ws_participant(State(app): State<App>, up: WebSocketUpgrade) -> Response {
    up.on_upgrade(move |s| feed(app, s, View::Participant))
}

async fn ws_experimenter(State(app): State<App>, up: WebSocketUpgrade) -> Response {
    up.on_upgrade(move |s| feed(app, s, View::Experimenter))
}

/// One page's socket: its view now, then every change; closed once the session is over.
async fn feed(app: App, mut socket: WebSocket, view: View) {
    let (mut rx, k) = match view {
        View::Participant => (app.shared.participant.subscribe(), 0),
        View::Experimenter => (app.shared.experimenter.subscribe(), 1),
    };
    let _open = PageOpen::new(&app.shared, k);
    rx.mark_changed();
    loop {
        tokio::select! {
            changed = rx.changed() => {
                if changed.is_err() {
                    return;
                }
                let (m, last) = rx.borrow_and_update().clone();
                if socket.send(Message::Text(m.into())).await.is_err() {
                    return;
                }
                if last {
                    let _ = socket.send(Message::Close(None)).await;
                    return;
                }
            },
            msg = socket.recv() => match msg {
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => return,
                Some(Ok(_)) => {}
            },
        }
    }
}

/// The address this machine is reached at from the lab's network, when listening on all of them:
/// the one its route to another network leaves from (a UDP connect only picks the route; nothing
/// is sent).
fn lan_ip() -> Option<IpAddr> {
    let s = UdpSocket::bind("0.0.0.0:0").ok()?;
    s.connect("192.0.2.1:9").ok()?;
    let ip = s.local_addr().ok()?.ip();
    (!ip.is_unspecified()).then_some(ip)
}

/// `host:port` for the printed URLs.
fn url_host(addr: SocketAddr) -> String {
    let ip = if addr.ip().is_unspecified() {
        lan_ip().unwrap_or(IpAddr::from([127, 0, 0, 1]))
    } else {
        addr.ip()
    };
    SocketAddr::new(ip, addr.port()).to_string()
}

impl Panel {
    /// Checks the address, binds, starts the server and the terminal's reader, prints the URLs
    /// (stderr; stdout too as a JSON line with `json`). Returns once the server listens.
    pub fn start(opts: PanelOptions) -> Result<Panel, Failure> {
        if let Some(warning) =
            check_listen(opts.listen, opts.allow_remote).map_err(Failure::input)?
        {
            eprintln!("{warning}");
        }
        let token = new_token().map_err(Failure::input)?;
        let std_listener = std::net::TcpListener::bind(opts.listen)
            .map_err(|e| Failure::input(format!("--panel {}: {e}", opts.listen)))?;
        std_listener
            .set_nonblocking(true)
            .map_err(|e| Failure::input(format!("--panel {}: {e}", opts.listen)))?;
        let addr = std_listener
            .local_addr()
            .map_err(|e| Failure::input(format!("--panel {}: {e}", opts.listen)))?;
        let p = &opts.protocol;
        let inner = Inner {
            seq: 0,
            prompt: Prompt::Starting,
            answer: None,
            mirror: None,
            mirror_tried: false,
            planned: Runner::new(p.clone(), &opts.subject, 0)
                .map(|r| r.planned_trials())
                .unwrap_or(0),
            at_most: p.blocks.iter().any(|b| b.design.name() == "staircase"),
            experiment: p.name.clone(),
            subject: opts.subject.clone(),
            explore_s: p.timing.explore_s,
            history: Vec::new(),
            pages: [0, 0],
        };
        let shared = Arc::new(Shared {
            participant: watch::Sender::new((participant_view(&inner).to_string(), false)),
            experimenter: watch::Sender::new((experimenter_view(&inner).to_string(), false)),
            inner: Mutex::new(inner),
            answered: Condvar::new(),
        });
        let app = App {
            shared: shared.clone(),
            token: token.clone().into(),
            cookie: format!("saw-panel-{}", addr.port()).into(),
        };
        let router = Router::new()
            .route("/", get(root))
            .route("/participant", get(page))
            .route("/experimenter", get(page))
            .route("/ws/participant", get(ws_participant))
            .route("/ws/experimenter", get(ws_experimenter))
            .route("/respond", post(respond))
            .route("/continue", post(continue_))
            .layer(DefaultBodyLimit::max(MAX_BODY))
            .layer(middleware::from_fn_with_state(app.clone(), guard))
            .with_state(app);
        let served = super::serve_thread(
            "saw-panel-http",
            std_listener,
            router,
            "the participant's panel did not start",
            "--panel",
        )
        .map_err(Failure::input)?;
        // The terminal answers too: Enter continues, a number answers; the first answer counts.
        // At the end of stdin (none attached) the pages alone answer.
        let reader = shared.clone();
        let _ = std::thread::Builder::new()
            .name("saw-panel-stdin".into())
            .spawn(move || {
                for line in std::io::stdin().lock().lines() {
                    match line {
                        Ok(l) => reader.typed(l.trim()),
                        Err(_) => return,
                    }
                }
            });
        let host = url_host(addr);
        let participant_url = format!("http://{host}/participant?token={token}");
        let experimenter_url = format!("http://{host}/experimenter?token={token}");
        eprintln!("saw experiment: the participant's page: {participant_url}");
        eprintln!("saw experiment: the experimenter's page: {experimenter_url}");
        if addr.ip().is_unspecified() {
            eprintln!(
                "saw experiment: listening on {addr} (every address of this machine; the URLs name the one its route out leaves from)"
            );
        }
        if opts.json {
            // A script reads where the pages are from stdout, as `saw --json ui` says where it
            // listens; the session's own answer is the last line.
            let mut out = std::io::stdout().lock();
            let _ = writeln!(
                out,
                "{}",
                json!({"ok": true, "result": {"panel": {
                    "participant": participant_url,
                    "experimenter": experimenter_url,
                    "listening": addr.to_string(),
                }}})
            );
            let _ = out.flush();
        }
        Ok(Panel {
            shared,
            protocol: opts.protocol,
            subject: opts.subject,
            subject_index: opts.subject_index,
            out: opts.out,
            stop: Some(served.stop),
            stopped: Some(served.stopped),
            participant_url,
            experimenter_url,
        })
    }

    /// Replays the session's log into a runner of our own once (the log exists by the first
    /// call), so that the views can say which trial and stimulus come now.
    fn mirror(&self) {
        let mut g = self.shared.lock();
        if g.mirror_tried {
            return;
        }
        g.mirror_tried = true;
        let log = session::Paths::new(&self.out, &self.subject).log;
        g.mirror = session::read_log(&log).ok().and_then(|read| {
            let index = self.subject_index.unwrap_or(read.header.subject_index);
            let replay: Vec<(u32, Vec<String>, i32)> = read
                .records
                .iter()
                .map(|r| {
                    (
                        r.number,
                        r.shown.iter().map(|s| s.stimulus.clone()).collect(),
                        r.response,
                    )
                })
                .collect();
            Runner::resume(self.protocol.clone(), &self.subject, index, &replay).ok()
        });
    }

    /// Asks `prompt` and waits for Continue (a page's or Enter).
    fn ask_continue(&self, prompt: Prompt) {
        let seq = self.shared.ask(prompt);
        if let Answer::Continue(Source::Page) = self.shared.wait(seq) {
            // The terminal's prompt line is left open: closed here, and said where it went on.
            eprintln!("(continued on a page)");
        }
    }
}

impl Participant for Panel {
    fn instructions(&mut self, text: &str) -> Result<(), Failure> {
        self.mirror();
        if !text.is_empty() {
            eprintln!("\n{text}\n");
        }
        eprint!("Begin on the participant's page, or press Enter here, to begin. ");
        self.ask_continue(Prompt::Instructions { text: text.into() });
        Ok(())
    }

    fn rest(&mut self, done: u32, planned: u32) -> Result<(), Failure> {
        self.mirror();
        eprint!(
            "Break ({done} of {planned} trials done): Continue on the participant's page, or Enter here, goes on. "
        );
        self.ask_continue(Prompt::Rest { done, planned });
        Ok(())
    }

    fn hand_over(&mut self, interval: usize, stimulus: &str, prompt: &str) -> Result<(), Failure> {
        self.mirror();
        eprint!(
            "[experimenter] interval {}: {prompt} ({stimulus}); \"In place\" on the experimenter's page, or Enter here, when it is in place. ",
            interval + 1
        );
        self.ask_continue(Prompt::HandOver {
            interval,
            stimulus: stimulus.into(),
            prompt: prompt.into(),
        });
        Ok(())
    }

    fn explore(&mut self, interval: usize, of: usize) {
        self.mirror();
        eprintln!("Explore {} of {of} now.", interval + 1);
        self.shared.ask(Prompt::Explore { interval, of });
    }

    fn respond(&mut self, trial: &Trial, shown: &[Shown]) -> Result<i32, Failure> {
        self.mirror();
        {
            // The mirror follows the session only while it agrees with it.
            let mut g = self.shared.lock();
            if g.mirror.as_ref().and_then(|m| m.next_trial()) != Some(trial) {
                g.mirror = None;
            }
        }
        eprintln!("{}", trial.question);
        for (v, w) in trial.values.iter().zip(&trial.words) {
            eprintln!("  {v:>3}  {w}");
        }
        eprint!("(on the participant's page, or here) > ");
        let _ = std::io::stderr().flush();
        let asked = Instant::now();
        let seq = self.shared.ask(Prompt::Question {
            trial: trial.clone(),
        });
        let (value, from) = match self.shared.wait(seq) {
            Answer::Value(v, from) => (v, from),
            // Only a value answers a question (`offer`).
            Answer::Continue(_) => unreachable!("a question answered by Continue"),
        };
        let mut g = self.shared.lock();
        let word = trial
            .values
            .iter()
            .position(|v| *v == value)
            .map_or(String::new(), |k| trial.words[k].clone());
        g.history.push(Line {
            number: trial.number,
            block: trial.block.clone(),
            stimuli: shown.iter().map(|s| s.stimulus.clone()).collect(),
            value,
            word,
            from,
            ms: asked.elapsed().as_secs_f64() * 1e3,
        });
        if from == Source::Page {
            eprintln!(
                "(answered on a page: {value}, {})",
                g.history[g.history.len() - 1].word
            );
        }
        if let Some(m) = g.mirror.as_mut() {
            if m.respond(value).is_err() {
                g.mirror = None;
            }
        }
        self.shared.publish(&g);
        Ok(value)
    }
}

impl Drop for Panel {
    /// The pages are told the session ended (over, or stopped early), then the server stops.
    fn drop(&mut self) {
        let finished = {
            let g = self.shared.lock();
            g.mirror.as_ref().is_some_and(|m| m.next_trial().is_none())
        };
        self.shared.ask(Prompt::Over { finished });
        if self.shared.lock().pages.iter().sum::<usize>() > 0 {
            std::thread::sleep(FAREWELL);
        }
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        // A connection that does not close does not hold the command's exit.
        if let Some(r) = self.stopped.take() {
            let _ = r.recv_timeout(Duration::from_secs(2));
        }
    }
}
