//! [`IphyreEnv`]: I-PHYRE behind the [`Environment`] trait.

use super::action::{Click, SCREEN, validate_clicks};
use super::game::{Game, Games};
use super::params::PhysicsParams;
use super::step::play;
use super::to_trace::trace_of;
use crate::envs::{ActionDim, EnvError, Environment};
use crate::trace::{Env, Trace};

/// The I-PHYRE environment: the 40 games and the physics constants.
#[derive(Debug, Clone)]
pub struct IphyreEnv {
    /// The games scenes are drawn from, in `GAMES` order.
    pub games: Games,
    /// Physics constants (60 fps by default).
    pub params: PhysicsParams,
}

impl IphyreEnv {
    /// The 40 committed games with iphyre's default physics.
    pub fn new() -> Result<IphyreEnv, EnvError> {
        Ok(IphyreEnv {
            games: Games::default_games()?,
            params: PhysicsParams::default(),
        })
    }

    /// The trace id [`Environment::simulate`] gives an episode: `<game>-clicks`.
    pub fn trace_id(game: &Game) -> String {
        format!("{}-clicks", game.name)
    }
}

impl Environment for IphyreEnv {
    type Scene = Game;
    type Action = Vec<Click>;

    fn env(&self) -> Env {
        Env::Iphyre
    }

    /// The games in `GAMES` order, cycling: scene `i` is game `i mod 40`; the games are fixed, so
    /// `seed` does not change them.
    fn scenes(&self, n: usize, seed: u64) -> Result<Vec<Game>, EnvError> {
        let _ = seed;
        let all = self.games.all();
        if all.is_empty() {
            return Ok(Vec::new());
        }
        Ok((0..n).map(|i| all[i % all.len()].clone()).collect())
    }

    /// One click: its screen position and time. An action is a list of such clicks.
    fn action_space(&self) -> Vec<ActionDim> {
        vec![
            ActionDim {
                name: "x",
                unit: "px",
                low: 0.0,
                high: SCREEN,
                doc: "click x on the 600×600 screen",
            },
            ActionDim {
                name: "y",
                unit: "px",
                low: 0.0,
                high: SCREEN,
                doc: "click y on the 600×600 screen, downwards",
            },
            ActionDim {
                name: "t",
                unit: "s",
                low: 0.0,
                high: self.params.max_time,
                doc: "click time; a click at exactly 0 is dropped, as in I-PHYRE",
            },
        ]
    }

    fn validate(&self, scene: &Game, action: &Vec<Click>) -> Result<(), EnvError> {
        let _ = scene;
        self.params.validate()?;
        validate_clicks(action, self.params.max_time)?;
        Ok(())
    }

    fn simulate(&self, scene: &Game, action: &Vec<Click>) -> Result<Trace, EnvError> {
        let result = play(scene, action, &self.params)?;
        Ok(trace_of(&result, scene, &IphyreEnv::trace_id(scene)))
    }

    /// The trace's timestep nearest to `t` at 512×512 in I-PHYRE's colours, with the time in the
    /// corner (see [`render`](super::render) for block indices and strips).
    fn render(&self, trace: &Trace, t: f64) -> Result<Vec<u8>, EnvError> {
        let game = self.games.get(&trace.task_id).ok();
        super::render::render_png(trace, game, t, &super::render::RenderOptions::default())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::iphyre::action::click_block;

    #[test]
    fn environment_cycles_the_games_and_simulates() {
        let mut env = IphyreEnv::new().unwrap();
        env.params = PhysicsParams::with_fps(10.0);
        let scenes = env.scenes(42, 7).unwrap();
        assert_eq!(
            (scenes[0].name.as_str(), scenes[41].name.as_str()),
            ("support", "hinder")
        );
        assert_eq!(env.action_space().len(), 3);
        let clicks = vec![
            click_block(&scenes[0], 0, 0.5).unwrap(),
            click_block(&scenes[0], 1, 0.5).unwrap(),
        ];
        env.validate(&scenes[0], &clicks).unwrap();
        let trace = env.simulate(&scenes[0], &clicks).unwrap();
        assert!(env.success(&trace));
        let png = env.render(&trace, 0.0).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        assert_eq!(trace.trace_id, "support-clicks");
        let bad = vec![Click {
            x: 0.0,
            y: 0.0,
            t: f64::INFINITY,
        }];
        assert!(env.validate(&scenes[0], &bad).is_err());
        assert!(env.simulate(&scenes[0], &bad).is_err());
    }
}
