// annotrace's vendored copy: the timer no longer reads the clock (see this crate's Cargo.toml). The
// world's profile fields it fed (`B2Profile`) are therefore always 0; the physics is unchanged.

pub struct B2timer {}

impl Default for B2timer
{
	/// Constructor
	fn default() -> Self {
		B2timer {}
	}
}

/// Timer for profiling, disabled: every reading is 0.
impl B2timer {

	/// reset the timer.
	pub fn reset(&mut self) {
	}

	/// Get the time since construction or the last reset (always 0 here).
	pub fn get_milliseconds(&self) -> f32 {
		0.0
	}
	pub fn precise_time_ns(&self) -> u64 {
		0
	}
}
