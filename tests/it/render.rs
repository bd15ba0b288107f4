//! `annotrace render`: a 512×512 PNG of a simulated billiards trace, a strip of frames, and errors.

use crate::common::{TestRun, example};
use annotrace::trace::Env;

/// Width and height from a PNG's IHDR chunk.
fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "a PNG file");
    let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    (w, h)
}

#[test]
fn renders_the_initial_table_and_a_strip() {
    let t = TestRun::new();
    t.run(&[
        "simulate", "--scenes", "1", "--seed", "3", "--dt", "0.05", "--run", "r",
    ])
    .ok();
    t.run(&[
        "render",
        "--run",
        "r",
        "--trace",
        "pool-3-000000-000",
        "--out",
        "first.png",
    ])
    .ok();
    assert_eq!(
        png_size(&std::fs::read(t.path("first.png")).unwrap()),
        (512, 512)
    );
    t.run(&[
        "render",
        "--run",
        "r",
        "--trace",
        "pool-3-000000-000",
        "--t",
        "1.5",
        "--out",
        "mid.png",
    ])
    .ok();
    assert_ne!(
        std::fs::read(t.path("mid.png")).unwrap(),
        std::fs::read(t.path("first.png")).unwrap()
    );
    t.run(&[
        "render",
        "--run",
        "r",
        "--trace",
        "pool-3-000000-000",
        "--frames",
        "3",
        "--out",
        "strip.png",
    ])
    .ok();
    assert_eq!(
        png_size(&std::fs::read(t.path("strip.png")).unwrap()),
        (1536, 512)
    );
}

#[test]
fn unknown_traces_and_other_environments_are_input_errors() {
    let t = TestRun::new();
    t.run(&[
        "simulate", "--scenes", "1", "--seed", "3", "--dt", "0.1", "--run", "r",
    ])
    .ok();
    t.run(&["render", "--run", "r", "--trace", "nope", "--out", "x.png"])
        .code(2)
        .stderr_has("nope");
    let phyre = example(Env::Phyre);
    t.run(&[
        "import",
        "--env",
        "phyre",
        phyre.to_str().unwrap(),
        "--run",
        "r",
    ])
    .ok();
    // PHYRE traces render too (docs/envs/phyre.md); the example's bodies do not match task 00000:000's,
    // so they are drawn from the trace's own shape and diameter.
    t.run(&[
        "render",
        "--run",
        "r",
        "--trace",
        "phyre_drop",
        "--out",
        "x.png",
    ])
    .ok();
    assert_eq!(&std::fs::read(t.path("x.png")).unwrap()[1..4], b"PNG");
}
