//! Any bytes through the paper-format JSON importer: the first byte picks the environment and the
//! layout (`.json` or JSON Lines), the rest is the file. Every input must end in traces and typed
//! errors — never a panic, an overflow or a hang — and every trace the importer accepts must be finite,
//! decode from its Arrow rows to itself and import from its own export to itself
//! (`testutil::import_round_trip`, the oracle the test suite's seeded sweep uses too).
#![no_main]

use annotrace::testutil::import_round_trip;
use annotrace::trace::Env;
use annotrace::trace::json::SourceKind;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, file)) = data.split_first() else {
        return;
    };
    let env = Env::ALL[usize::from(pick & 0x0f) % Env::ALL.len()];
    let kind = if pick & 0x80 != 0 {
        SourceKind::JsonLines
    } else {
        SourceKind::Json
    };
    if let Err(e) = import_round_trip(file, kind, env) {
        panic!("{env} {kind:?}: {e}");
    }
});
