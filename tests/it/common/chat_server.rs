//! `ChatServer`: a small local HTTP server that speaks the OpenAI chat-completions protocol and answers
//! from a script, so the real LLM client can be tested without a model: good answers (with or without
//! `usage`), HTTP errors with `Retry-After`, slow answers, bodies that are not chat completions, and an
//! echo of the `Authorization` header. One thread per connection (std only); every request is kept for
//! the test to inspect, and the most requests in flight at once are counted.

#![allow(dead_code)]

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use serde_json::{Value, json};

/// One scripted answer.
#[derive(Clone, Debug)]
pub enum Reply {
    /// 200 with a chat completion whose message is `content`; `usage` adds token counts.
    Chat {
        content: String,
        usage: Option<(u64, u64)>,
    },
    /// An HTTP error status with a body and an optional `Retry-After` value.
    Status {
        code: u16,
        retry_after: Option<String>,
        body: String,
    },
    /// Waits, then answers.
    Slow { delay: Duration, then: Box<Reply> },
    /// Any status and body as is.
    Raw { code: u16, body: String },
    /// 200 with a completion whose content is the request's `Authorization` header.
    EchoAuth,
}

impl Reply {
    /// A completion with usage (prompt 100, completion 20 tokens).
    pub fn chat(content: &str) -> Reply {
        Reply::Chat {
            content: content.to_string(),
            usage: Some((100, 20)),
        }
    }
    /// A completion without `usage`.
    pub fn chat_no_usage(content: &str) -> Reply {
        Reply::Chat {
            content: content.to_string(),
            usage: None,
        }
    }
    /// An error status.
    pub fn status(code: u16) -> Reply {
        Reply::Status {
            code,
            retry_after: None,
            body: format!("{{\"error\":\"scripted {code}\"}}"),
        }
    }
    /// 429 with `Retry-After: <value>`.
    pub fn too_many(retry_after: &str) -> Reply {
        Reply::Status {
            code: 429,
            retry_after: Some(retry_after.to_string()),
            body: "{\"error\":\"rate limited\"}".into(),
        }
    }
    /// `then` after `ms` milliseconds.
    pub fn slow(ms: u64, then: Reply) -> Reply {
        Reply::Slow {
            delay: Duration::from_millis(ms),
            then: Box::new(then),
        }
    }
}

/// A request the server received.
#[derive(Clone, Debug)]
pub struct Seen {
    pub path: String,
    pub authorization: Option<String>,
    pub body: Value,
}

impl Seen {
    /// The text of the last message.
    pub fn last_message(&self) -> String {
        self.body["messages"]
            .as_array()
            .and_then(|m| m.last())
            .and_then(|m| m["content"].as_str())
            .unwrap_or("")
            .to_string()
    }
}

type Responder = Box<dyn Fn(&Seen) -> Reply + Send + Sync>;

struct State {
    script: VecDeque<Reply>,
    responder: Option<Responder>,
    seen: Vec<Seen>,
    in_flight: usize,
    max_in_flight: usize,
}

/// The running server; stops when dropped.
pub struct ChatServer {
    addr: SocketAddr,
    state: Arc<Mutex<State>>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl ChatServer {
    /// A server answering requests with `script`, in order; past its end it answers 418.
    pub fn start(script: Vec<Reply>) -> ChatServer {
        Self::launch(script, None)
    }

    /// A server answering every request with `f(request)`.
    pub fn responder(f: impl Fn(&Seen) -> Reply + Send + Sync + 'static) -> ChatServer {
        Self::launch(Vec::new(), Some(Box::new(f)))
    }

    fn launch(script: Vec<Reply>, responder: Option<Responder>) -> ChatServer {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind a local port");
        let addr = listener.local_addr().unwrap();
        let state = Arc::new(Mutex::new(State {
            script: script.into(),
            responder,
            seen: Vec::new(),
            in_flight: 0,
            max_in_flight: 0,
        }));
        let stop = Arc::new(AtomicBool::new(false));
        let (st, sp) = (state.clone(), stop.clone());
        let handle = std::thread::spawn(move || {
            for conn in listener.incoming() {
                if sp.load(Ordering::SeqCst) {
                    break;
                }
                let Ok(stream) = conn else { continue };
                let st = st.clone();
                std::thread::spawn(move || serve(stream, &st));
            }
        });
        ChatServer {
            addr,
            state,
            stop,
            handle: Some(handle),
        }
    }

    /// The base URL to configure (`http://127.0.0.1:<port>`).
    pub fn url(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// Every request received so far.
    pub fn seen(&self) -> Vec<Seen> {
        self.state.lock().unwrap().seen.clone()
    }

    /// The most requests that were being answered at the same time.
    pub fn max_in_flight(&self) -> usize {
        self.state.lock().unwrap().max_in_flight
    }

    /// Scripted answers not used yet.
    pub fn remaining(&self) -> usize {
        self.state.lock().unwrap().script.len()
    }
}

impl Drop for ChatServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = TcpStream::connect(self.addr);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn serve(stream: TcpStream, state: &Mutex<State>) {
    let mut reader = BufReader::new(stream.try_clone().expect("clone stream"));
    let mut request_line = String::new();
    if reader.read_line(&mut request_line).unwrap_or(0) == 0 {
        return; // the shutdown poke, or a client that went away
    }
    let path = request_line
        .split_whitespace()
        .nth(1)
        .unwrap_or("")
        .to_string();
    let mut length = 0usize;
    let mut authorization = None;
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).unwrap_or(0) == 0 {
            return;
        }
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        if let Some((k, v)) = line.split_once(':') {
            match k.trim().to_ascii_lowercase().as_str() {
                "content-length" => length = v.trim().parse().unwrap_or(0),
                "authorization" => authorization = Some(v.trim().to_string()),
                _ => {}
            }
        }
    }
    let mut body = vec![0u8; length];
    if reader.read_exact(&mut body).is_err() {
        return;
    }
    let seen = Seen {
        path,
        authorization,
        body: serde_json::from_slice(&body).unwrap_or(Value::Null),
    };
    let reply = {
        let mut st = state.lock().unwrap();
        st.seen.push(seen.clone());
        st.in_flight += 1;
        st.max_in_flight = st.max_in_flight.max(st.in_flight);
        match &st.responder {
            Some(f) => f(&seen),
            None => st.script.pop_front().unwrap_or(Reply::Raw {
                code: 418,
                body: "chat_server: the script has no answer left".into(),
            }),
        }
    };
    let mut stream = stream;
    answer(&mut stream, reply, &seen);
    state.lock().unwrap().in_flight -= 1;
}

fn answer(stream: &mut TcpStream, reply: Reply, seen: &Seen) {
    let (code, extra, body) = match reply {
        Reply::Slow { delay, then } => {
            std::thread::sleep(delay);
            return answer(stream, *then, seen);
        }
        Reply::Chat { content, usage } => {
            let mut v = json!({
                "id": "chatcmpl-test",
                "object": "chat.completion",
                "model": seen.body["model"],
                "choices": [{"index": 0, "message": {"role": "assistant", "content": content},
                             "finish_reason": "stop"}],
            });
            if let Some((p, c)) = usage {
                v["usage"] =
                    json!({"prompt_tokens": p, "completion_tokens": c, "total_tokens": p + c});
            }
            (200, String::new(), v.to_string())
        }
        Reply::EchoAuth => {
            let content = seen.authorization.clone().unwrap_or_default();
            let v = json!({"choices": [{"message": {"role": "assistant", "content": content}}]});
            (200, String::new(), v.to_string())
        }
        Reply::Status {
            code,
            retry_after,
            body,
        } => {
            let extra = retry_after
                .map(|r| format!("Retry-After: {r}\r\n"))
                .unwrap_or_default();
            (code, extra, body)
        }
        Reply::Raw { code, body } => (code, String::new(), body),
    };
    let head = format!(
        "HTTP/1.1 {code} Scripted\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n{extra}\r\n",
        body.len()
    );
    let _ = stream.write_all(head.as_bytes());
    let _ = stream.write_all(body.as_bytes());
    let _ = stream.flush();
}
