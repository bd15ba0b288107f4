//! A pymunk episode recorded by `tools/iphyre_chipmunk_steps.py` (its text format is documented there):
//! the space it starts from, the removals, and what the original reported after each step. Shared by
//! the `replay` example and the `pymunk_replay` test.

use std::collections::HashMap;

use chipmunk_step::{
    Body, Constraint, DampedSpring, Geometry, PinJoint, Space, Vect, default_bias,
};

/// One recorded episode.
pub struct Recording {
    /// The space as the original built it, before the first step.
    pub space: Space,
    /// The time step.
    pub dt: f64,
    /// Bodies removed (with their shapes and constraints) before a step.
    pub removals: HashMap<usize, Vec<usize>>,
    /// Per step: (body, [px, py, angle, vx, vy, w]) of every dynamic body.
    pub states: HashMap<usize, Vec<(usize, [f64; 6])>>,
    /// Per step: the contacts in solver order, `A:B:N …`.
    pub orders: HashMap<usize, String>,
    /// Per step: each contact's normal and points, as written.
    pub contacts: HashMap<usize, Vec<String>>,
    /// Per checkpoint step: the running digest ([`Digest`]).
    pub digests: Vec<(usize, u64)>,
    /// Whether the original solved the game, and its steps.
    pub success: bool,
    /// Steps the original ran.
    pub steps: usize,
}

fn num(s: &str) -> f64 {
    s.parse().unwrap_or_else(|_| panic!("not a number: {s:?}"))
}

fn int(s: &str) -> usize {
    s.parse()
        .unwrap_or_else(|_| panic!("not an integer: {s:?}"))
}

impl Recording {
    /// Parses a recording; panics on a malformed line (the files are made by the tool).
    pub fn parse(text: &str) -> Recording {
        let mut r = Recording {
            space: Space::new(Vect::ZERO),
            dt: 0.0,
            removals: HashMap::new(),
            states: HashMap::new(),
            orders: HashMap::new(),
            contacts: HashMap::new(),
            digests: Vec::new(),
            success: false,
            steps: 0,
        };
        for line in text.lines() {
            let f: Vec<&str> = line.split_whitespace().collect();
            match f.first().copied() {
                Some("space") => {
                    r.space = Space::new(Vect::new(num(f[1]), num(f[2])));
                    r.space.iterations = int(f[3]);
                    r.dt = num(f[4]);
                }
                Some("body") => {
                    let p = Vect::new(num(f[5]), num(f[6]));
                    assert_eq!(num(f[7]), 0.0, "initial angles are 0");
                    let body = if f[2] == "dynamic" {
                        Body::dynamic(num(f[3]), num(f[4]), p)
                    } else {
                        Body::fixed(p)
                    };
                    assert_eq!(r.space.add_body(body), int(f[1]));
                }
                Some("circle") => {
                    let g = Geometry::Circle {
                        offset: Vect::ZERO,
                        r: num(f[2]),
                    };
                    r.space.add_shape(int(f[1]), g, num(f[3]), num(f[4]));
                }
                Some("segment") => {
                    let g = Geometry::Segment {
                        a: Vect::new(num(f[2]), num(f[3])),
                        b: Vect::new(num(f[4]), num(f[5])),
                        r: num(f[6]),
                    };
                    r.space.add_shape(int(f[1]), g, num(f[7]), num(f[8]));
                }
                Some("pin") => {
                    let j = PinJoint::new(
                        r.space.bodies(),
                        int(f[1]),
                        int(f[2]),
                        Vect::ZERO,
                        Vect::ZERO,
                        default_bias(),
                    );
                    r.space.add_constraint(Constraint::Pin(j));
                }
                Some("spring") => {
                    let s = DampedSpring::new(
                        int(f[1]),
                        int(f[2]),
                        Vect::ZERO,
                        Vect::ZERO,
                        num(f[3]),
                        num(f[4]),
                        num(f[5]),
                    );
                    r.space.add_constraint(Constraint::Spring(s));
                }
                Some("remove") => r.removals.entry(int(f[1])).or_default().push(int(f[2])),
                Some("state") => {
                    let v = [f[3], f[4], f[5], f[6], f[7], f[8]].map(num);
                    r.states.entry(int(f[1])).or_default().push((int(f[2]), v));
                }
                Some("arbiters") => {
                    r.orders.insert(int(f[1]), f[2..].join(" "));
                }
                Some("contact") => r
                    .contacts
                    .entry(int(f[1]))
                    .or_default()
                    .push(f[2..].join(" ")),
                Some("digest") => r.digests.push((
                    int(f[1]),
                    u64::from_str_radix(f[2], 16).expect("a hex digest"),
                )),
                Some("result") => {
                    r.success = f[1] == "1";
                    r.steps = int(f[2]);
                }
                _ => {}
            }
        }
        r
    }
}

/// The contacts of the space's last step in solver order, as the recording writes them.
pub fn order_of(space: &Space) -> String {
    space
        .contacts()
        .map(|(a, b, n)| format!("{a}:{b}:{n}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The running digest of the recording tool: 64-bit FNV-1a over, per step, every live dynamic body's
/// index and state bits, then the step's contact order.
pub struct Digest(pub u64);

impl Digest {
    pub fn new() -> Digest {
        Digest(0xCBF2_9CE4_8422_2325)
    }

    fn bytes(&mut self, data: &[u8]) {
        for &b in data {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x100_0000_01B3);
        }
    }

    /// Adds one step of `space`.
    pub fn step(&mut self, space: &Space) {
        for (i, body) in space.bodies().iter().enumerate() {
            if !space.is_alive(i) || body.kind != chipmunk_step::BodyKind::Dynamic {
                continue;
            }
            self.bytes(&(i as u64).to_le_bytes());
            for v in [body.p.x, body.p.y, body.angle, body.v.x, body.v.y, body.w] {
                self.bytes(&v.to_le_bytes());
            }
        }
        self.bytes(order_of(space).as_bytes());
    }
}
