//! Progress on the terminal: bars when stderr is a terminal, one plain line per event otherwise.

use std::collections::HashMap;
use std::io::IsTerminal;
use std::sync::Mutex;

use annotrace::pipeline::Progress;
use indicatif::{ProgressBar, ProgressStyle};

/// Shows stage progress on stderr.
pub struct Terminal {
    bars: Mutex<HashMap<String, ProgressBar>>,
    tty: bool,
    quiet: bool,
}

impl Terminal {
    pub fn new(quiet: bool) -> Self {
        Terminal {
            bars: Mutex::new(HashMap::new()),
            tty: std::io::stderr().is_terminal(),
            quiet,
        }
    }

    fn bar(&self, stage: &str) -> Option<ProgressBar> {
        self.bars.lock().ok()?.get(stage).cloned()
    }
}

impl Progress for Terminal {
    fn stage_started(&self, stage: &str, kind: &str, total: Option<u64>) {
        if self.quiet {
            return;
        }
        if self.tty {
            let bar = ProgressBar::new(total.unwrap_or(0));
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix:.bold} {bar:30} {pos}/{len} {elapsed_precise} {msg}",
                )
                .expect("valid template"),
            );
            bar.set_prefix(format!("{stage} ({kind})"));
            if let Ok(mut bars) = self.bars.lock() {
                bars.insert(stage.to_string(), bar);
            }
        } else {
            eprintln!("[{stage}] started ({kind})");
        }
    }

    fn set_total(&self, stage: &str, total: u64) {
        if let Some(bar) = self.bar(stage) {
            bar.set_length(total);
        }
    }

    fn advance(&self, stage: &str, n: u64) {
        match self.bar(stage) {
            Some(bar) => bar.inc(n),
            None if !self.quiet && !self.tty => {}
            None => {}
        }
    }

    fn note(&self, stage: &str, message: &str) {
        if self.quiet {
            return;
        }
        match self.bar(stage) {
            Some(bar) => bar.println(format!("[{stage}] {message}")),
            None => eprintln!("[{stage}] {message}"),
        }
    }

    fn stage_finished(&self, stage: &str, summary: &str) {
        if let Some(bar) = self.bars.lock().ok().and_then(|mut b| b.remove(stage)) {
            bar.finish_and_clear();
        }
        if !self.quiet {
            eprintln!("[{stage}] done: {summary}");
        }
    }

    fn stage_cached(&self, stage: &str) {
        if !self.quiet {
            eprintln!("[{stage}] cached (fingerprint unchanged)");
        }
    }
}
