//! The spending meter: calls and tokens used so far against the [`Budget`] caps.

use std::sync::Mutex;

use super::config::Budget;
use super::error::LlmError;

/// What a client has spent so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Usage {
    /// Logical calls started (retries count once), replayed ones included.
    pub calls: u64,
    /// Of those, answered from a recording.
    pub replayed: u64,
    /// Prompt tokens.
    pub tokens_in: u64,
    /// Completion tokens.
    pub tokens_out: u64,
    /// HTTP requests sent (first attempts and retries).
    pub requests: u64,
}

impl Usage {
    /// Prompt plus completion tokens.
    pub fn tokens(&self) -> u64 {
        self.tokens_in + self.tokens_out
    }
}

/// Counts spending and refuses calls past the caps.
#[derive(Debug, Default)]
pub(crate) struct Meter {
    budget: Budget,
    used: Mutex<Usage>,
}

impl Meter {
    pub fn new(budget: Budget) -> Self {
        Meter {
            budget,
            used: Mutex::new(Usage::default()),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Usage> {
        self.used.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Takes one call from the budget, or says which cap is reached.
    pub fn reserve(&self) -> Result<(), LlmError> {
        let mut u = self.lock();
        if let Some(max) = self.budget.max_calls
            && u.calls >= max
        {
            return Err(LlmError::BudgetExhausted {
                what: format!("{} of max_calls = {max} calls made", u.calls),
            });
        }
        if let Some(max) = self.budget.max_tokens
            && u.tokens() >= max
        {
            return Err(LlmError::BudgetExhausted {
                what: format!("{} of max_tokens = {max} tokens used", u.tokens()),
            });
        }
        u.calls += 1;
        Ok(())
    }

    pub fn add_tokens(&self, tokens_in: u64, tokens_out: u64, replayed: bool) {
        let mut u = self.lock();
        u.tokens_in += tokens_in;
        u.tokens_out += tokens_out;
        if replayed {
            u.replayed += 1;
        }
    }

    pub fn add_request(&self) {
        self.lock().requests += 1;
    }

    pub fn usage(&self) -> Usage {
        *self.lock()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calls_and_tokens_are_capped() {
        let m = Meter::new(Budget {
            max_calls: Some(2),
            max_tokens: None,
        });
        m.reserve().unwrap();
        m.reserve().unwrap();
        assert!(m.reserve().unwrap_err().is_budget());
        let t = Meter::new(Budget {
            max_calls: None,
            max_tokens: Some(100),
        });
        t.reserve().unwrap();
        t.add_tokens(60, 50, false);
        let e = t.reserve().unwrap_err();
        assert!(e.to_string().contains("110 of max_tokens = 100"), "{e}");
        assert_eq!(t.usage().tokens(), 110);
    }
}
