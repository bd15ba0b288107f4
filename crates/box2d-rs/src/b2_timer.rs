// Vendored change (annotrace, PATCHES.md): the timer does not read the clock. Box2D's timers only fill
// the world's profile (`B2world::get_profile`) and the time-of-impact statistics, which nothing in
// annotrace reads; reading the clock several times per step and per time-of-impact query cost 10-13 %
// of a PHYRE episode's CPU. Every time it reports is 0.

/// Timer for profiling (here a no-op: see the note above).
#[derive(Default, Clone, Copy, Debug)]
pub struct B2timer;

impl B2timer {
	/// reset the timer.
	pub fn reset(&mut self) {}

	/// Get the time since construction or the last reset: always 0 here.
	pub fn get_milliseconds(&self) -> f32 {
		0.0
	}

	/// Nanoseconds since construction or the last reset: always 0 here.
	pub fn precise_time_ns(&self) -> u64 {
		0
	}
}
