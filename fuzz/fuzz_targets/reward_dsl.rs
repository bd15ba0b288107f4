//! Any text through the reward DSL (lex, parse, check against the built-in pooltool library, evaluate
//! on a synthetic billiards trace) and through the verification-rule parser and evaluator: every input
//! must give a value or a `RewardError`, never a panic, overflow or hang.
#![no_main]

use std::sync::OnceLock;

use annotrace::detect::Library;
use annotrace::reward::verify::Rule;
use annotrace::reward::{AnnotatedTrace, Schema, compile, evaluate};
use annotrace::testutil::synthetic_trace;
use annotrace::trace::{Env, Trace};
use libfuzzer_sys::fuzz_target;

fn fixtures() -> &'static (Schema, Trace) {
    static F: OnceLock<(Schema, Trace)> = OnceLock::new();
    F.get_or_init(|| {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/libraries/pooltool");
        let lib = Library::load(&dir).expect("the built-in library loads");
        (Schema::from_library(&lib), synthetic_trace(Env::Pooltool, 0, 50, 10))
    })
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let (schema, trace) = fixtures();
    if let Ok(program) = compile(text, schema) {
        let at = AnnotatedTrace::new(trace, std::iter::empty());
        if let Ok(e) = evaluate(&program, &at) {
            assert!((0.0..=1.0).contains(&e.score));
        }
    }
    if let Ok(rule) = Rule::parse(text) {
        let _ = rule.holds(trace);
    }
});
