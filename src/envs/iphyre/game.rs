//! The 40 I-PHYRE games as data: blocks (capsule segments), balls, pin joints and springs, loaded from
//! the JSON written by `tools/phyre/iphyre_export.py games` (iphyre 0.2.3, MIT; the committed copy
//! is `data/games/iphyre_games.json`, docs/envs/iphyre.md §R1 and §R7).

use serde::Deserialize;

use super::error::{IphyreError, Result};

/// The committed games document (`data/games/iphyre_games.json`).
pub const DEFAULT_GAMES_JSON: &str = include_str!("../../../data/games/iphyre_games.json");

/// The four folds of ten games, in I-PHYRE's `FOLD_LIST` order.
pub const FOLDS: [&str; 4] = ["basic", "noisy", "compositional", "multi_ball"];

/// What an object is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectKind {
    /// A thick line segment (a capsule of radius 10 px between its two ends).
    Block,
    /// A circle.
    Ball,
}

/// One object of a game in its initial state (screen pixels, origin top-left, y down).
#[derive(Debug, Clone, PartialEq)]
pub struct GameObject {
    /// Original object index: blocks first, then balls.
    pub index: usize,
    /// Block or ball.
    pub kind: ObjectKind,
    /// First end (a ball: its centre).
    pub p1: [f64; 2],
    /// Second end (a ball: its centre again).
    pub p2: [f64; 2],
    /// Capsule radius (10 px for every block) or ball radius (px).
    pub radius: f64,
    /// Whether a click can remove it (only static blocks are).
    pub eliminable: bool,
    /// Whether it moves (balls and dynamic blocks).
    pub dynamic: bool,
    /// 1-based index of the pin joint it belongs to, 0 for none (the observation's `joint` column).
    pub joint: i64,
    /// 1-based index of the spring it belongs to, 0 for none (the observation's `spring` column).
    pub spring: i64,
}

impl GameObject {
    /// The segment midpoint (a ball: its centre); bodies are placed here.
    pub fn centre(&self) -> [f64; 2] {
        [
            (self.p1[0] + self.p2[0]) / 2.0,
            (self.p1[1] + self.p2[1]) / 2.0,
        ]
    }

    /// Segment length (0 for a ball).
    pub fn length(&self) -> f64 {
        (self.p2[0] - self.p1[0]).hypot(self.p2[1] - self.p1[1])
    }
}

/// One game: its objects and the constraints between them.
#[derive(Debug, Clone, PartialEq)]
pub struct Game {
    /// The game's name (`support`, `noisy_hinder`, `multi_ball_stack`, …).
    pub name: String,
    /// Position in I-PHYRE's `GAMES` list (0–39).
    pub index: usize,
    /// Its fold (one of [`FOLDS`]).
    pub fold: String,
    /// Every object, indexed by [`GameObject::index`].
    pub objects: Vec<GameObject>,
    /// Pin joints (rigid rods between body centres) as pairs of object indices.
    pub joints: Vec<[usize; 2]>,
    /// Damped springs between body centres as pairs of object indices.
    pub springs: Vec<[usize; 2]>,
}

impl Game {
    /// The blocks, in object order.
    pub fn blocks(&self) -> impl Iterator<Item = &GameObject> {
        self.objects.iter().filter(|o| o.kind == ObjectKind::Block)
    }

    /// The balls, in object order.
    pub fn balls(&self) -> impl Iterator<Item = &GameObject> {
        self.objects.iter().filter(|o| o.kind == ObjectKind::Ball)
    }

    /// The eliminable blocks, in object order (what the discrete action "remove block k" counts).
    pub fn eliminable(&self) -> impl Iterator<Item = &GameObject> {
        self.objects.iter().filter(|o| o.eliminable)
    }
}

/// The loaded games, in `GAMES` order.
#[derive(Debug, Clone, PartialEq)]
pub struct Games {
    games: Vec<Game>,
}

#[derive(Deserialize)]
struct RawDoc {
    games: Vec<RawGame>,
}

#[derive(Deserialize)]
struct RawGame {
    name: String,
    index: usize,
    fold: String,
    #[serde(default)]
    joints: Vec<[usize; 2]>,
    #[serde(default)]
    springs: Vec<[usize; 2]>,
    objects: Vec<RawObject>,
}

#[derive(Deserialize)]
struct RawObject {
    index: usize,
    kind: String,
    x1: f64,
    y1: f64,
    x2: f64,
    y2: f64,
    radius: f64,
    eliminable: u8,
    dynamic: u8,
    #[serde(default)]
    joint: Vec<i64>,
    #[serde(default)]
    spring: Vec<i64>,
}

impl Games {
    /// The 40 committed games ([`DEFAULT_GAMES_JSON`]).
    pub fn default_games() -> Result<Games> {
        Games::from_json(DEFAULT_GAMES_JSON)
    }

    /// Parses and checks a games document in `iphyre_export.py games` format.
    pub fn from_json(text: &str) -> Result<Games> {
        let doc: RawDoc = serde_json::from_str(text)?;
        let mut games = Vec::with_capacity(doc.games.len());
        for (gi, raw) in doc.games.into_iter().enumerate() {
            games.push(convert(gi, raw)?);
        }
        Ok(Games { games })
    }

    /// Every game, in `GAMES` order.
    pub fn all(&self) -> &[Game] {
        &self.games
    }

    /// The game called `name`.
    pub fn get(&self, name: &str) -> Result<&Game> {
        self.games.iter().find(|g| g.name == name).ok_or_else(|| {
            let names: Vec<&str> = self
                .games
                .iter()
                .take(10)
                .map(|g| g.name.as_str())
                .collect();
            IphyreError::UnknownGame {
                name: name.to_string(),
                known: format!("{}, …", names.join(", ")),
            }
        })
    }

    /// The games of one fold, in `GAMES` order.
    pub fn fold(&self, fold: &str) -> Vec<&Game> {
        self.games.iter().filter(|g| g.fold == fold).collect()
    }
}

fn bad(field: String, message: impl Into<String>) -> IphyreError {
    IphyreError::InvalidGame {
        field,
        message: message.into(),
    }
}

fn convert(gi: usize, raw: RawGame) -> Result<Game> {
    let at = |rest: &str| format!("games[{gi}]{rest}");
    if !FOLDS.contains(&raw.fold.as_str()) {
        return Err(bad(at(".fold"), format!("unknown fold {:?}", raw.fold)));
    }
    let mut objects = Vec::with_capacity(raw.objects.len());
    for (oi, o) in raw.objects.into_iter().enumerate() {
        let field = |name: &str| at(&format!(".objects[{oi}].{name}"));
        if o.index != oi {
            return Err(bad(field("index"), format!("{} (expected {oi})", o.index)));
        }
        let kind = match o.kind.as_str() {
            "block" => ObjectKind::Block,
            "ball" => ObjectKind::Ball,
            other => return Err(bad(field("kind"), format!("unknown kind {other:?}"))),
        };
        for (name, v) in [("x1", o.x1), ("y1", o.y1), ("x2", o.x2), ("y2", o.y2)] {
            if !v.is_finite() {
                return Err(bad(field(name), "not finite"));
            }
        }
        if !(o.radius.is_finite() && o.radius > 0.0) {
            return Err(bad(
                field("radius"),
                format!("{} is not a positive radius", o.radius),
            ));
        }
        let object = GameObject {
            index: oi,
            kind,
            p1: [o.x1, o.y1],
            p2: [o.x2, o.y2],
            radius: o.radius,
            eliminable: o.eliminable != 0,
            dynamic: o.dynamic != 0,
            joint: o.joint.first().copied().unwrap_or(0),
            spring: o.spring.first().copied().unwrap_or(0),
        };
        if object.eliminable && object.dynamic {
            return Err(bad(
                field("eliminable"),
                "an object cannot be both eliminable and dynamic",
            ));
        }
        if kind == ObjectKind::Ball && !object.dynamic {
            return Err(bad(field("dynamic"), "balls must be dynamic"));
        }
        if kind == ObjectKind::Block && object.length() <= 0.0 {
            return Err(bad(field("x2"), "a block needs two distinct ends"));
        }
        objects.push(object);
    }
    let n = objects.len();
    for (name, pairs) in [("joints", &raw.joints), ("springs", &raw.springs)] {
        for (pi, [a, b]) in pairs.iter().enumerate() {
            if *a >= n || *b >= n || a == b {
                return Err(bad(
                    at(&format!(".{name}[{pi}]")),
                    format!("[{a}, {b}] is not a pair of distinct object indices below {n}"),
                ));
            }
        }
    }
    Ok(Game {
        name: raw.name,
        index: raw.index,
        fold: raw.fold,
        objects,
        joints: raw.joints,
        springs: raw.springs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loads_forty_games_ten_per_fold() {
        let games = Games::default_games().unwrap();
        assert_eq!(games.all().len(), 40);
        for fold in FOLDS {
            assert_eq!(games.fold(fold).len(), 10, "fold {fold}");
        }
        for (i, g) in games.all().iter().enumerate() {
            assert_eq!(g.index, i);
            assert!(g.objects.len() <= 12, "{}", g.name);
            let eli = g.eliminable().count();
            assert!((2..=6).contains(&eli), "{}: {eli} eliminable", g.name);
            assert!(g.balls().count() >= 1, "{}", g.name);
        }
        assert_eq!(games.get("multi_ball_stack").unwrap().balls().count(), 6);
    }

    #[test]
    fn support_game_matches_the_reference_table() {
        let games = Games::default_games().unwrap();
        let g = games.get("support").unwrap();
        assert_eq!(g.fold, "basic");
        assert_eq!(g.blocks().count(), 2);
        let ball = g.balls().next().unwrap();
        assert_eq!((ball.p1, ball.radius), ([250.0, 340.0], 20.0));
        assert!(g.objects[0].eliminable && !g.objects[0].dynamic);
        assert_eq!(g.objects[0].radius, 10.0);
    }

    #[test]
    fn constraints_are_read() {
        let games = Games::default_games().unwrap();
        assert_eq!(games.get("pendulum").unwrap().joints, vec![[5, 6]]);
        assert!(!games.get("spring").unwrap().springs.is_empty());
        let with_joints = games.all().iter().filter(|g| !g.joints.is_empty()).count();
        let with_springs = games.all().iter().filter(|g| !g.springs.is_empty()).count();
        assert_eq!((with_joints, with_springs), (5, 6));
    }

    #[test]
    fn bad_documents_name_the_field() {
        let err = Games::get(&Games::default_games().unwrap(), "nope").unwrap_err();
        assert!(err.to_string().contains("\"nope\""));
        let text = r#"{"games":[{"name":"x","index":0,"fold":"basic","joints":[[0,5]],"objects":[
            {"index":0,"kind":"ball","x1":1,"y1":1,"x2":1,"y2":1,"radius":5,"eliminable":0,"dynamic":1}]}]}"#;
        let err = Games::from_json(text).unwrap_err().to_string();
        assert!(err.contains("games[0].joints[0]"), "{err}");
        assert!(Games::from_json("{").is_err());
    }
}
