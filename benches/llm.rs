//! LLM client overhead: what annotrace itself spends per model call, apart from the model.
//!
//! `cargo bench --bench llm`. Measured: rendering the code-evolution prompt (billiards, two parents of
//! 40 lines), extracting the program from a 3 kB answer (prose, a helper block, the detector block),
//! and whole `LlmClient::chat` round trips to an in-process HTTP server that answers at once (so the
//! time is the client's: request body, hashing, the HTTP exchange over loopback, parsing, the
//! `llm_calls` row and its Parquet files every 16 calls), one caller and four callers on four slots.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpListener;
use std::sync::Arc;
use std::time::{Duration, Instant};

use annotrace::fitness::FitnessTerms;
use annotrace::llm::{
    ChatRequest, EvolveContext, LlmClient, LlmConfig, ParentView, Prompts, extract_code,
};
use annotrace::store::RunDir;
use annotrace::trace::Env;

fn parent(i: usize) -> String {
    let mut code = String::from("def find_pattern(trace):\n    out = []\n");
    for k in 0..38 {
        code.push_str(&format!(
            "    x{k} = len(trace.get(\"timesteps\", [])) * {i} + {k}\n"
        ));
    }
    code.push_str("    return out\n");
    code
}

fn answer() -> String {
    let mut a = String::from("I kept the event check and tightened the span.\n\n");
    a.push_str("```python\ndef _speed(o):\n    v = o[\"velocity\"]\n    return (v[0] ** 2 + v[1] ** 2) ** 0.5\n```\n\n");
    a.push_str("Now the detector:\n\n```python\n");
    a.push_str(&parent(1));
    a.push_str("```\n\nThis should fire only on the rebound frames. ");
    a.push_str(&"It is short and avoids brittle thresholds. ".repeat(30));
    a
}

/// A server answering every request at once with a fixed completion.
fn serve() -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let body = serde_json::json!({
        "choices": [{"message": {"role": "assistant", "content": answer()}, "finish_reason": "stop"}],
        "usage": {"prompt_tokens": 900, "completion_tokens": 300}
    })
    .to_string();
    std::thread::spawn(move || {
        for conn in listener.incoming() {
            let Ok(stream) = conn else { continue };
            let body = body.clone();
            std::thread::spawn(move || {
                let mut r = BufReader::new(stream.try_clone().unwrap());
                let mut len = 0;
                loop {
                    let mut line = String::new();
                    if r.read_line(&mut line).unwrap_or(0) == 0 {
                        return;
                    }
                    let l = line.trim_end().to_ascii_lowercase();
                    if l.is_empty() {
                        break;
                    }
                    if let Some(v) = l.strip_prefix("content-length:") {
                        len = v.trim().parse().unwrap_or(0);
                    }
                }
                let mut buf = vec![0; len];
                if r.read_exact(&mut buf).is_err() {
                    return;
                }
                let mut s = stream;
                let _ = write!(
                    s,
                    "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                    body.len()
                );
            });
        }
    });
    url
}

fn report(what: &str, n: usize, d: Duration) {
    println!(
        "{what:<58} {n:>6} × {:>9.1} µs   ({:>8.0} /s)",
        d.as_secs_f64() * 1e6 / n as f64,
        n as f64 / d.as_secs_f64()
    );
}

fn main() {
    let prompts = Prompts::builtin();
    let f = FitnessTerms::new(0.6, 0.3, 0.7, 0.0);
    let ctx = EvolveContext {
        env: Env::Pooltool,
        label: "cushion rebound".into(),
        step: 10,
        island: 0,
        parents: (0..2)
            .map(|i| ParentView::new(&parent(i), 40, Some(&f)))
            .collect(),
        library_labels: vec!["cue strike".into(), "ball collision".into()],
    };
    let n = 2000;
    let t = Instant::now();
    for _ in 0..n {
        std::hint::black_box(prompts.render("evolve.j2", &ctx).unwrap());
    }
    report(
        "render evolve.j2 (pooltool, 2 parents × 40 lines)",
        n,
        t.elapsed(),
    );

    let a = answer();
    let n = 20_000;
    let t = Instant::now();
    for _ in 0..n {
        std::hint::black_box(extract_code(std::hint::black_box(&a)).unwrap());
    }
    report(
        &format!("extract_code ({} B answer, 2 blocks)", a.len()),
        n,
        t.elapsed(),
    );

    let url = serve();
    let prompt = prompts.render("evolve.j2", &ctx).unwrap();
    for (callers, slots) in [(1usize, 1usize), (4, 4)] {
        let dir = tempfile::tempdir().unwrap();
        let mut config = LlmConfig::new(url.clone(), "bench");
        config.parallel = slots;
        let client = Arc::new(LlmClient::new(config, Some(&RunDir::new(dir.path()))).unwrap());
        let per = 400 / callers;
        let t = Instant::now();
        let handles: Vec<_> = (0..callers)
            .map(|c| {
                let (client, prompt) = (client.clone(), prompt.clone());
                std::thread::spawn(move || {
                    for i in 0..per {
                        let req = ChatRequest::new("bench")
                            .user(prompt.clone())
                            .seed((c * per + i) as u64);
                        std::hint::black_box(client.chat(&req).unwrap());
                    }
                })
            })
            .collect();
        for h in handles {
            h.join().unwrap();
        }
        client.flush().unwrap();
        report(
            &format!("chat round trip, recorded ({callers} caller(s), {slots} slot(s))"),
            per * callers,
            t.elapsed(),
        );
    }
}
