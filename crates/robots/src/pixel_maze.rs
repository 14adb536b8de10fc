//! p2's crowd-navigation maze, observed as a 16×16 RGB image, in two layouts.
//!
//! p2 (section 2, figure 1): a bird's-eye view where a blue agent must reach a static green goal
//! while red obstacles ("people") patrol along a line, turning around at the boundary; obstacles
//! are placed at random with a random direction at every reset; a collision gives −5, and the
//! agent earns +1 for every step it stays on the goal ("the faster it reaches the goal, the more
//! positive reward"). The paper gives no grid size, obstacle count, start or episode length.
//! Both layouts share the rules below and differ in what the paper leaves open
//! ([`PixelMazeLayout`]):
//!
//! | | `PixelMaze-v0` (ours) | `PixelMaze-v1` (the authors' released environment) |
//! |---|---|---|
//! | grid | 8 × 8 cells of 2 × 2 pixels | 16 × 16 cells of one pixel |
//! | obstacles | 2, each on a row or column in `1..=6`, moving along it | 5, on any free cell, moving in any of the four directions |
//! | agent start | a uniformly random cell that no obstacle occupies now or after its next move | the bottom-left cell `(0, 15)` |
//! | goal | the bottom-right cell `(7, 7)` | the top-right cell `(15, 0)` |
//! | a collision | ends the episode | does not end it (the agent can collide again) |
//! | episode (the registered [`tandem_envs::TimeLimit`]) | 50 steps | 100 steps |
//!
//! `PixelMaze-v1` follows the maze in the code the authors published with p2 (its grid, object
//! size, obstacle count and placement, start, goal, episode length and non-terminating
//! collisions), with p2's −5 for a collision. `PixelMaze-v0` was built from the paper alone;
//! its random starts next to the goal make it much easier: DQN alone solves it in about 260
//! episodes, where p2 reports 700.
//!
//! Rules common to both:
//!
//! - the image is `16 × 16 × 3` (row-major, height × width × channel, values 0 or 1;
//!   observation space `Box(16x16x3) [0, 1]`); the agent sets the blue channel, the goal green,
//!   obstacles red (so the agent on the goal is cyan);
//! - actions `Discrete(5)` as in p2: 0 left, 1 right, 2 up ("forward"), 3 down ("backward"),
//!   4 wait; a move into the boundary leaves the agent where it is;
//! - each step every obstacle moves one cell along its direction, reversing first when that
//!   cell is outside the grid;
//! - agent and obstacles move at the same time; a collision (same cell afterwards, or the two
//!   swapping cells) gives `collision_reward` (−5); otherwise being on the goal gives
//!   `goal_reward` (+1); every other step gives 0.
//!
//! State for [`Env::state`]/[`Env::set_state`]: `[agent_x, agent_y, (x, y, dx, dy) per obstacle]`
//! with cell coordinates (x to the right, y down) and unit directions.

use rand::Rng as _;
use tandem_core::seeding::{rng_from_seed, Rng};
use tandem_core::{Action, Space};

use tandem_envs::{check_action, check_state, Phase};
use tandem_envs::{Env, EnvError, Step};

/// `PixelMaze-v0`'s grid cells per side.
pub const PIXEL_MAZE_GRID: usize = 8;
/// Image pixels per side, in both layouts.
pub const PIXEL_MAZE_PIXELS: usize = 16;
/// `PixelMaze-v0`'s number of moving obstacles.
pub const PIXEL_MAZE_OBSTACLES: usize = 2;

/// Where a layout puts its obstacles at reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObstaclePlacement {
    /// On a row or a column strictly inside the grid (never the border lines, so never through
    /// a corner), moving along it in either direction.
    InnerLines,
    /// On any cell that the agent, the goal and the obstacles placed before do not occupy,
    /// moving in any of the four directions.
    Anywhere,
}

/// What p2 leaves open about its maze: the two registered layouts are [`PixelMazeLayout::v0`]
/// and [`PixelMazeLayout::v1`] (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PixelMazeLayout {
    /// Grid cells per side; each cell is `16 / grid` pixels wide, so `grid` divides 16.
    pub grid: usize,
    /// Number of obstacles.
    pub obstacles: usize,
    /// Where the obstacles start.
    pub placement: ObstaclePlacement,
    /// The agent's start cell `(x, y)`, or `None` for a random one off the obstacles.
    pub start: Option<(i64, i64)>,
    /// The goal cell `(x, y)`.
    pub goal: (i64, i64),
    /// Whether a collision ends the episode.
    pub collision_ends_episode: bool,
}

impl PixelMazeLayout {
    /// `PixelMaze-v0`'s layout (ours, from the paper alone).
    pub fn v0() -> Self {
        Self {
            grid: PIXEL_MAZE_GRID,
            obstacles: PIXEL_MAZE_OBSTACLES,
            placement: ObstaclePlacement::InnerLines,
            start: None,
            goal: (PIXEL_MAZE_GRID as i64 - 1, PIXEL_MAZE_GRID as i64 - 1),
            collision_ends_episode: true,
        }
    }

    /// `PixelMaze-v1`'s layout (the authors' released maze).
    pub fn v1() -> Self {
        Self {
            grid: 16,
            obstacles: 5,
            placement: ObstaclePlacement::Anywhere,
            start: Some((0, 15)),
            goal: (15, 0),
            collision_ends_episode: false,
        }
    }
}

/// One patrolling obstacle: cell and unit direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Obstacle {
    x: i64,
    y: i64,
    dx: i64,
    dy: i64,
}

impl Obstacle {
    /// One step along the patrol line, turning around at the boundary of a `g × g` grid.
    fn advance(&mut self, g: i64) {
        let inside = |v: i64| (0..g).contains(&v);
        if !inside(self.x + self.dx) || !inside(self.y + self.dy) {
            self.dx = -self.dx;
            self.dy = -self.dy;
        }
        self.x += self.dx;
        self.y += self.dy;
    }
}

/// p2's maze as a pixel environment (see the module documentation).
#[derive(Debug, Clone)]
pub struct PixelMazeEnv {
    id: &'static str,
    layout: PixelMazeLayout,
    agent: (i64, i64),
    obstacles: Vec<Obstacle>,
    phase: Phase,
    rng: Rng,
    collision_reward: f64,
    goal_reward: f64,
    observation_space: Space,
    action_space: Space,
}

impl Default for PixelMazeEnv {
    fn default() -> Self {
        Self::new()
    }
}

impl PixelMazeEnv {
    /// The registered id of the layout built from the paper alone.
    pub const ID: &'static str = "PixelMaze-v0";
    /// The registered id of the authors' released layout.
    pub const ID_V1: &'static str = "PixelMaze-v1";
    /// `PixelMaze-v0`'s goal cell `(x, y)`.
    pub const GOAL: (i64, i64) = (PIXEL_MAZE_GRID as i64 - 1, PIXEL_MAZE_GRID as i64 - 1);

    /// `PixelMaze-v0` with p2's rewards (−5 collision, +1 per step on the goal); its generator
    /// starts from seed 0 until a seeded `reset`.
    pub fn new() -> Self {
        Self::build(Self::ID, PixelMazeLayout::v0())
    }

    /// `PixelMaze-v1`, the authors' released layout, with p2's rewards.
    pub fn v1() -> Self {
        Self::build(Self::ID_V1, PixelMazeLayout::v1())
    }

    /// The registered maze `id` (`PixelMaze-v0` or `PixelMaze-v1`), if it is one.
    pub fn from_id(id: &str) -> Option<Self> {
        match id {
            Self::ID => Some(Self::new()),
            Self::ID_V1 => Some(Self::v1()),
            _ => None,
        }
    }

    fn build(id: &'static str, layout: PixelMazeLayout) -> Self {
        let n = PIXEL_MAZE_PIXELS * PIXEL_MAZE_PIXELS * 3;
        Self {
            id,
            agent: layout.start.unwrap_or((0, 0)),
            obstacles: vec![
                Obstacle {
                    x: 1,
                    y: 1,
                    dx: 1,
                    dy: 0,
                };
                layout.obstacles
            ],
            layout,
            phase: Phase::NotReset,
            rng: rng_from_seed(0),
            collision_reward: -5.0,
            goal_reward: 1.0,
            observation_space: Space::Box {
                low: vec![0.0; n],
                high: vec![1.0; n],
                shape: vec![PIXEL_MAZE_PIXELS, PIXEL_MAZE_PIXELS, 3],
            },
            action_space: Space::discrete(5),
        }
    }

    /// The layout.
    pub fn layout(&self) -> &PixelMazeLayout {
        &self.layout
    }

    fn g(&self) -> i64 {
        self.layout.grid as i64
    }

    /// The image of the current state: `16 × 16 × 3`, row-major (y, x, channel), as f64 0/1.
    pub fn render(&self) -> Vec<f64> {
        let w = PIXEL_MAZE_PIXELS;
        let cell = w / self.layout.grid;
        let mut img = vec![0.0; w * w * 3];
        let mut paint = |(x, y): (i64, i64), c: usize| {
            for py in 0..cell {
                for px in 0..cell {
                    let (ix, iy) = (x as usize * cell + px, y as usize * cell + py);
                    img[(iy * w + ix) * 3 + c] = 1.0;
                }
            }
        };
        paint(self.layout.goal, 1);
        for o in &self.obstacles {
            paint((o.x, o.y), 0);
        }
        paint(self.agent, 2);
        img
    }

    fn collides(&self, before: &[Obstacle], agent_before: (i64, i64)) -> bool {
        self.obstacles.iter().zip(before).any(|(o, b)| {
            let now = (o.x, o.y);
            now == self.agent || (now == agent_before && (b.x, b.y) == self.agent)
        })
    }

    fn place_on_inner_lines(&mut self) {
        let g = self.g();
        for o in &mut self.obstacles {
            let line = self.rng.random_range(1..g - 1);
            let along = self.rng.random_range(0..g);
            let sign = if self.rng.random::<bool>() { 1 } else { -1 };
            *o = if self.rng.random::<bool>() {
                Obstacle {
                    x: along,
                    y: line,
                    dx: sign,
                    dy: 0,
                }
            } else {
                Obstacle {
                    x: line,
                    y: along,
                    dx: 0,
                    dy: sign,
                }
            };
        }
    }

    fn place_anywhere(&mut self) {
        let g = self.g();
        let mut taken = vec![self.layout.goal];
        taken.extend(self.layout.start);
        for k in 0..self.obstacles.len() {
            let cell = loop {
                let c = (self.rng.random_range(0..g), self.rng.random_range(0..g));
                if !taken.contains(&c) {
                    break c;
                }
            };
            taken.push(cell);
            let (dx, dy) = [(1, 0), (-1, 0), (0, 1), (0, -1)][self.rng.random_range(0..4)];
            self.obstacles[k] = Obstacle {
                x: cell.0,
                y: cell.1,
                dx,
                dy,
            };
        }
    }
}

impl Env for PixelMazeEnv {
    fn id(&self) -> &str {
        self.id
    }

    fn observation_space(&self) -> &Space {
        &self.observation_space
    }

    fn action_space(&self) -> &Space {
        &self.action_space
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        if let Some(s) = seed {
            self.rng = rng_from_seed(s);
        }
        match self.layout.placement {
            ObstaclePlacement::InnerLines => self.place_on_inner_lines(),
            ObstaclePlacement::Anywhere => self.place_anywhere(),
        }
        self.agent = match self.layout.start {
            Some(cell) => cell,
            None => {
                // Any cell but the goal and the obstacles' cells now and after their move.
                let g = self.g();
                let mut blocked = vec![self.layout.goal];
                for o in &self.obstacles {
                    let mut next = *o;
                    next.advance(g);
                    blocked.extend([(o.x, o.y), (next.x, next.y)]);
                }
                loop {
                    let c = (self.rng.random_range(0..g), self.rng.random_range(0..g));
                    if !blocked.contains(&c) {
                        break c;
                    }
                }
            }
        };
        self.phase = Phase::Running;
        self.render()
    }

    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        self.phase.check(self.id)?;
        check_action(self.id, &self.action_space, action)?;
        let (dx, dy) = match action.as_discrete() {
            Some(0) => (-1, 0),
            Some(1) => (1, 0),
            Some(2) => (0, -1),
            Some(3) => (0, 1),
            _ => (0, 0),
        };
        let g = self.g();
        let agent_before = self.agent;
        let (x, y) = (self.agent.0 + dx, self.agent.1 + dy);
        if (0..g).contains(&x) && (0..g).contains(&y) {
            self.agent = (x, y);
        }
        let before = self.obstacles.clone();
        self.obstacles.iter_mut().for_each(|o| o.advance(g));
        let collided = self.collides(&before, agent_before);
        let terminated = collided && self.layout.collision_ends_episode;
        if terminated {
            self.phase = Phase::Ended;
        }
        let reward = if collided {
            self.collision_reward
        } else if self.agent == self.layout.goal {
            self.goal_reward
        } else {
            0.0
        };
        Ok(Step {
            observation: self.render(),
            reward,
            terminated,
            truncated: false,
        })
    }

    fn state(&self) -> Vec<f64> {
        let mut s = vec![self.agent.0 as f64, self.agent.1 as f64];
        for o in &self.obstacles {
            s.extend([o.x as f64, o.y as f64, o.dx as f64, o.dy as f64]);
        }
        s
    }

    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f64>, EnvError> {
        check_state(self.id, state, 2 + 4 * self.obstacles.len())?;
        let g = self.g();
        let bad = |reason: String| EnvError::InvalidState {
            env: self.id.to_string(),
            reason,
        };
        let cell = |i: usize| -> Result<i64, EnvError> {
            let v = state[i];
            if v.fract() == 0.0 && (0.0..g as f64).contains(&v) {
                Ok(v as i64)
            } else {
                Err(bad(format!(
                    "component {i} = {v} is not a cell index in 0..{g}"
                )))
            }
        };
        let agent = (cell(0)?, cell(1)?);
        let mut obstacles = self.obstacles.clone();
        for (k, o) in obstacles.iter_mut().enumerate() {
            let b = 2 + 4 * k;
            let (dx, dy) = (state[b + 2], state[b + 3]);
            let unit = matches!(
                (dx as i64, dy as i64, dx.fract() == 0.0 && dy.fract() == 0.0),
                (1 | -1, 0, true) | (0, 1 | -1, true)
            );
            if !unit {
                return Err(bad(format!(
                    "obstacle {k} direction ({dx}, {dy}) is not a unit axis step"
                )));
            }
            *o = Obstacle {
                x: cell(b)?,
                y: cell(b + 1)?,
                dx: dx as i64,
                dy: dy as i64,
            };
        }
        self.agent = agent;
        self.obstacles = obstacles;
        self.phase = Phase::Running;
        Ok(self.render())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pixel(img: &[f64], px: usize, py: usize) -> [f64; 3] {
        let i = (py * PIXEL_MAZE_PIXELS + px) * 3;
        [img[i], img[i + 1], img[i + 2]]
    }

    /// Agent at (ax, ay); obstacles far away on vertical lines that never reach it.
    fn quiet_state(ax: f64, ay: f64) -> Vec<f64> {
        vec![ax, ay, 3.0, 0.0, 0.0, 1.0, 5.0, 7.0, 0.0, -1.0]
    }

    #[test]
    fn rendering_draws_each_cell_as_a_2x2_block_in_its_channel() {
        let mut e = PixelMazeEnv::new();
        let img = e
            .set_state(&[2.0, 1.0, 4.0, 6.0, 1.0, 0.0, 6.0, 3.0, 0.0, 1.0])
            .unwrap();
        assert_eq!(img.len(), 16 * 16 * 3);
        // Agent (2, 1): pixels x 4..6, y 2..4 blue.
        for (px, py) in [(4, 2), (5, 2), (4, 3), (5, 3)] {
            assert_eq!(pixel(&img, px, py), [0.0, 0.0, 1.0]);
        }
        // Goal (7, 7): pixels 14..16 green; obstacles red at (4, 6) and (6, 3).
        assert_eq!(pixel(&img, 15, 15), [0.0, 1.0, 0.0]);
        assert_eq!(pixel(&img, 8, 12), [1.0, 0.0, 0.0]);
        assert_eq!(pixel(&img, 13, 7), [1.0, 0.0, 0.0]);
        // Exactly 4 cells lit (16 pixels), one channel each.
        assert_eq!(img.iter().sum::<f64>(), 16.0);
        // Agent on the goal: cyan.
        let img = e.set_state(&quiet_state(7.0, 7.0)).unwrap();
        assert_eq!(pixel(&img, 14, 14), [0.0, 1.0, 1.0]);
        assert_eq!(e.observation_space().flat_dim(), 768);
        assert!(matches!(e.observation_space(), Space::Box { shape, .. } if shape == &[16, 16, 3]));
    }

    #[test]
    fn the_shortest_path_reaches_the_goal_and_waiting_there_pays_every_step() {
        let mut e = PixelMazeEnv::new();
        e.set_state(&quiet_state(0.0, 0.0)).unwrap();
        // 7 right, 7 down: 14 moves, rewards 0 until the last one.
        let mut rewards = Vec::new();
        for a in [1; 7].into_iter().chain([3; 7]) {
            rewards.push(e.step(&Action::Discrete(a)).unwrap().reward);
        }
        assert_eq!(&rewards[..13], &[0.0; 13]);
        assert_eq!(rewards[13], 1.0);
        assert_eq!(&e.state()[..2], &[7.0, 7.0]);
        // Pushing into the boundary and waiting keep it on the goal: +1 each step.
        for a in [1, 3, 4] {
            let st = e.step(&Action::Discrete(a)).unwrap();
            assert_eq!((st.reward, st.terminated), (1.0, false));
        }
        // Left leaves the goal.
        assert_eq!(e.step(&Action::Discrete(0)).unwrap().reward, 0.0);
    }

    #[test]
    fn obstacles_patrol_and_turn_around_at_the_boundary() {
        let mut e = PixelMazeEnv::new();
        // Obstacle 0 at x = 6 moving right along row 3; obstacle 1 at y = 1 moving up in column 5.
        e.set_state(&[0.0, 0.0, 6.0, 3.0, 1.0, 0.0, 5.0, 1.0, 0.0, -1.0])
            .unwrap();
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for _ in 0..4 {
            e.step(&Action::Discrete(4)).unwrap();
            let s = e.state();
            xs.push(s[2]);
            ys.push(s[7]);
            assert_eq!(s[3], 3.0);
            assert_eq!(s[6], 5.0);
        }
        assert_eq!(xs, vec![7.0, 6.0, 5.0, 4.0]);
        assert_eq!(ys, vec![0.0, 1.0, 2.0, 3.0]);
    }

    #[test]
    fn collisions_terminate_with_minus_five_including_swaps() {
        let mut e = PixelMazeEnv::new();
        // Obstacle moving left along row 0... rows are 1..=6 at reset, but set_state may place
        // any cell: the obstacle at (2, 0) moving left meets the agent moving right into (1, 0).
        e.set_state(&[0.0, 0.0, 2.0, 0.0, -1.0, 0.0, 5.0, 7.0, 0.0, -1.0])
            .unwrap();
        let st = e.step(&Action::Discrete(1)).unwrap();
        assert_eq!((st.reward, st.terminated), (-5.0, true));
        assert!(matches!(
            e.step(&Action::Discrete(4)),
            Err(EnvError::NeedsReset { .. })
        ));
        // Swap: agent (1, 0) → (2, 0) while the obstacle goes (2, 0) → (1, 0).
        e.set_state(&[1.0, 0.0, 2.0, 0.0, -1.0, 0.0, 5.0, 7.0, 0.0, -1.0])
            .unwrap();
        let st = e.step(&Action::Discrete(1)).unwrap();
        assert_eq!((st.reward, st.terminated), (-5.0, true));
        // Passing next to each other is not a collision.
        e.set_state(&[1.0, 1.0, 2.0, 0.0, -1.0, 0.0, 5.0, 7.0, 0.0, -1.0])
            .unwrap();
        let st = e.step(&Action::Discrete(4)).unwrap();
        assert_eq!((st.reward, st.terminated), (0.0, false));
    }

    #[test]
    fn resets_are_seeded_start_off_the_obstacles_and_keep_the_goal_off_patrol_lines() {
        let mut a = PixelMazeEnv::new();
        let mut b = PixelMazeEnv::new();
        assert_eq!(a.reset(Some(3)), b.reset(Some(3)));
        assert_eq!(a.state(), b.state());
        let mut starts = std::collections::HashSet::new();
        let mut layouts = std::collections::HashSet::new();
        for seed in 0..200 {
            a.reset(Some(seed));
            let s = a.state();
            let agent = (s[0], s[1]);
            assert_ne!(agent, (7.0, 7.0));
            starts.insert((s[0] as i64, s[1] as i64));
            layouts.insert(s.iter().map(|v| *v as i64).collect::<Vec<_>>());
            for k in 0..PIXEL_MAZE_OBSTACLES {
                let o = &s[2 + 4 * k..6 + 4 * k];
                // The fixed coordinate (the line) lies in 1..=6.
                let line = if o[2] != 0.0 { o[1] } else { o[0] };
                assert!((1.0..=6.0).contains(&line), "{o:?}");
                assert_ne!(agent, (o[0], o[1]), "started on an obstacle");
            }
            // Waiting one step never collides; no obstacle ever enters the goal cell.
            let st = a.step(&Action::Discrete(4)).unwrap();
            assert!(!st.terminated, "seed {seed}: collision on the first step");
            for _ in 0..60 {
                let s = a.state();
                for k in 0..PIXEL_MAZE_OBSTACLES {
                    assert_ne!((s[2 + 4 * k], s[3 + 4 * k]), (7.0, 7.0));
                }
                if a.step(&Action::Discrete(4)).unwrap().terminated {
                    break;
                }
            }
        }
        assert!(starts.len() > 40, "{}", starts.len());
        assert!(layouts.len() > 150, "{}", layouts.len());
    }

    /// `PixelMaze-v1` with the agent at (ax, ay) and five obstacles on columns 3..=7 moving
    /// down from row 0: far from the bottom-left corner and from the goal's row for a while.
    fn v1_state(ax: f64, ay: f64) -> Vec<f64> {
        let mut s = vec![ax, ay];
        for k in 0..5 {
            s.extend([3.0 + k as f64, 0.0, 0.0, 1.0]);
        }
        s
    }

    #[test]
    fn v1_draws_one_pixel_per_cell_and_starts_in_the_bottom_left_corner() {
        let mut e = PixelMazeEnv::v1();
        assert_eq!(e.id(), "PixelMaze-v1");
        let img = e.set_state(&v1_state(0.0, 15.0)).unwrap();
        assert_eq!(pixel(&img, 0, 15), [0.0, 0.0, 1.0]);
        assert_eq!(pixel(&img, 15, 0), [0.0, 1.0, 0.0]);
        for k in 0..5 {
            assert_eq!(pixel(&img, 3 + k, 0), [1.0, 0.0, 0.0]);
        }
        // Seven objects, one pixel each.
        assert_eq!(img.iter().sum::<f64>(), 7.0);
        assert!(e.set_state(&v1_state(16.0, 0.0)).is_err());
        assert!(
            e.set_state(&quiet_state(0.0, 0.0)).is_err(),
            "v0's state length"
        );

        let mut directions = std::collections::HashSet::new();
        for seed in 0..100 {
            e.reset(Some(seed));
            let s = e.state();
            assert_eq!(&s[..2], &[0.0, 15.0]);
            let cells: Vec<(i64, i64)> = (0..5)
                .map(|k| (s[2 + 4 * k] as i64, s[3 + 4 * k] as i64))
                .collect();
            for (k, c) in cells.iter().enumerate() {
                assert!(*c != (0, 15) && *c != (15, 0), "seed {seed}: {c:?}");
                assert!(
                    !cells[..k].contains(c),
                    "seed {seed}: two obstacles on {c:?}"
                );
                directions.insert((s[4 + 4 * k] as i64, s[5 + 4 * k] as i64));
            }
        }
        assert_eq!(directions.len(), 4);
    }

    #[test]
    fn v1_shortest_path_takes_thirty_moves_and_collisions_go_on() {
        let mut e = PixelMazeEnv::v1();
        e.set_state(&v1_state(0.0, 15.0)).unwrap();
        // Obstacles on columns 3..=7 moving down reach row 15 after 15 steps: go up first along
        // column 0, then right along row 0 once they have left it.
        let mut rewards = Vec::new();
        for a in [2; 15].into_iter().chain([1; 15]) {
            let st = e.step(&Action::Discrete(a)).unwrap();
            assert!(!st.terminated);
            rewards.push(st.reward);
        }
        assert_eq!(&rewards[..29], &[0.0; 29]);
        assert_eq!(rewards[29], 1.0);
        assert_eq!(&e.state()[..2], &[15.0, 0.0]);

        // A collision costs −5 and the episode goes on; the next step can collide again.
        let mut s = v1_state(5.0, 5.0);
        s[2..6].copy_from_slice(&[5.0, 4.0, 0.0, 1.0]); // moving down onto the waiting agent
        s[6..10].copy_from_slice(&[5.0, 7.0, 0.0, -1.0]); // and one moving up, a step behind
        e.set_state(&s).unwrap();
        let st = e.step(&Action::Discrete(4)).unwrap();
        assert_eq!((st.reward, st.terminated), (-5.0, false));
        let st = e.step(&Action::Discrete(4)).unwrap();
        assert_eq!((st.reward, st.terminated), (-5.0, false));
        assert_eq!(e.step(&Action::Discrete(0)).unwrap().reward, 0.0);
    }

    #[test]
    fn bad_actions_and_states_are_errors() {
        let mut e = PixelMazeEnv::new();
        assert!(matches!(
            e.step(&Action::Discrete(0)),
            Err(EnvError::NeedsReset { .. })
        ));
        e.reset(Some(0));
        assert!(e.step(&Action::Discrete(5)).is_err());
        assert!(e.step(&Action::Continuous(vec![0.0])).is_err());
        assert!(e.set_state(&[0.0; 3]).is_err());
        assert!(e.set_state(&quiet_state(8.0, 0.0)).is_err());
        assert!(e.set_state(&quiet_state(0.5, 0.0)).is_err());
        let mut s = quiet_state(0.0, 0.0);
        s[4] = 1.0; // direction (1, 1)
        assert!(e.set_state(&s).is_err());
    }
}
