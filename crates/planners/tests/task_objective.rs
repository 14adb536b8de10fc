//! A task's reward and termination as a planning objective. Truth: the environment itself (an
//! objective from a task scores an action sequence as the environment's rewards do), and a task
//! whose termination changes the optimum (a cliff the unterminated objective would run over).

use nalgebra::DVector;
use ndarray::Array2;
use tandem_core::seeding::rng_from_seed;
use tandem_core::{Action, Rng, Space};
use tandem_dynamics::classic::GymPendulum;
use tandem_dynamics::Plant;
use tandem_envs::{clip_to, Env, PendulumTask, PlantEnv, Task};
use tandem_models::PlantModel;
use tandem_planners::{Bounds, Cem, CemConfig, Ilqr, IlqrConfig, Objective, Plan, Planner};

#[test]
fn a_task_objective_scores_a_sequence_as_the_environment_rewards_it() {
    let plant = GymPendulum::default();
    let task = PendulumTask::new(plant.params());
    let objective = Objective::from_task(task.clone()).unwrap();
    let x0 = [2.5, -0.5];
    // 3 N m is outside the bounds: the objective clips it as the environment does.
    let actions = Array2::from_shape_vec((4, 1), vec![1.0, 3.0, -2.0, 0.5]).unwrap();
    let model = PlantModel::new(plant);
    let plan = Plan::rollout(&x0, &model, &objective, &actions, &mut rng_from_seed(0)).unwrap();

    let mut env = PlantEnv::from_parts(plant, task).unwrap();
    env.set_state(&x0).unwrap();
    let rewards: Vec<f64> = actions
        .rows()
        .into_iter()
        .map(|a| env.step(&Action::Continuous(a.to_vec())).unwrap().reward)
        .collect();
    for (c, r) in plan.costs.iter().zip(&rewards) {
        assert_eq!(*c, -r);
    }
    assert_eq!(plan.total_cost, -rewards.iter().sum::<f64>());
    assert_eq!(plan.states.row(4).to_vec(), env.state());
    assert_eq!(plan.terminal_step, None);
}

/// A point that walks along a line, `x' = x + u` with `|u| ≤ 1`, earning its progress and 1 per
/// step alive; the episode ends past the cliff at `x = 2.5`.
#[derive(Clone)]
struct Cliff {
    observation_space: Space,
    action_space: Space,
}

impl Cliff {
    fn new() -> Self {
        Self {
            observation_space: Space::unbounded(1),
            action_space: Space::symmetric(1, 1.0),
        }
    }
}

impl Task for Cliff {
    fn id(&self) -> &str {
        "Cliff-v0"
    }
    fn observation_space(&self) -> &Space {
        &self.observation_space
    }
    fn action_space(&self) -> &Space {
        &self.action_space
    }
    fn state_dim(&self) -> usize {
        1
    }
    fn control(&self, action: &Action) -> Vec<f64> {
        clip_to(&self.action_space, action.as_continuous().unwrap_or(&[0.0]))
    }
    fn initial_state(&self, _rng: &mut Rng) -> Vec<f64> {
        vec![0.0]
    }
    fn observe(&self, state: &[f64]) -> Vec<f64> {
        state.to_vec()
    }
    fn reward(&self, state: &[f64], _u: &[f64], next: &[f64]) -> f64 {
        next[0] - state[0] + 1.0
    }
    fn terminated(&self, next: &[f64]) -> bool {
        next[0] > 2.5
    }
    fn max_episode_steps(&self) -> Option<usize> {
        None
    }
}

struct Walk;

impl Plant for Walk {
    fn state_dim(&self) -> usize {
        1
    }
    fn action_dim(&self) -> usize {
        1
    }
    fn dt(&self) -> f64 {
        1.0
    }
    fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
        x + u
    }
}

#[test]
fn a_terminated_sample_costs_nothing_after_its_terminal_step() {
    let objective = Objective::from_task(Cliff::new()).unwrap();
    let model = PlantModel::new(Walk);
    let run = Array2::from_elem((5, 1), 1.0);
    let plan = Plan::rollout(&[0.0], &model, &objective, &run, &mut rng_from_seed(0)).unwrap();
    // x = 1, 2, 3: the third step crosses the cliff; its reward counts, later ones do not.
    assert_eq!(plan.costs.to_vec(), vec![-2.0, -2.0, -2.0, 0.0, 0.0]);
    assert_eq!(plan.total_cost, -6.0);
    assert_eq!(plan.terminal_step, Some(2));
    assert_eq!(
        plan.states.column(0).to_vec(),
        vec![0.0, 1.0, 2.0, 3.0, 3.0, 3.0]
    );
    let data = plan.transitions();
    assert_eq!(data.terminated.to_vec(), vec![false, false, true]);
    assert_eq!(data.next_states[(2, 0)], 3.0);
}

#[test]
fn planning_with_termination_stops_short_of_the_cliff() {
    let cem = |objective: &Objective| {
        let mut cem = Cem::new(CemConfig {
            horizon: 5,
            population: 400,
            iterations: 8,
            bounds: Some(Bounds::symmetric(1, 1.0)),
            ..CemConfig::default()
        })
        .unwrap();
        cem.plan(&[0.0], &PlantModel::new(Walk), objective).unwrap()
    };
    // Walking to the edge and over it on the last step (five steps alive, 3.5 of progress) beats
    // crossing any earlier: crossing at step h earns at most h + 1 + min(h + 1, 3.5).
    let plan = cem(&Objective::from_task(Cliff::new()).unwrap());
    assert!(plan.states[(4, 0)] <= 2.5, "{:?}", plan.states);
    assert!(
        (-8.5..-8.3).contains(&plan.total_cost),
        "{}",
        plan.total_cost
    );
    // Without the termination, running is best: −(5 + 5).
    let task = Cliff::new();
    let free = Objective::from_transition_reward(1, 1, move |x, u, next| task.reward(x, u, next));
    assert!(cem(&free).total_cost < -9.5);
}

#[test]
fn trajectory_optimizers_refuse_costs_they_cannot_expand() {
    let objective = Objective::from_task(Cliff::new()).unwrap();
    let err = Ilqr::new(IlqrConfig::default())
        .unwrap()
        .solve(
            &PlantModel::new(Walk),
            &objective,
            &[0.0],
            &Array2::zeros((5, 1)),
        )
        .unwrap_err();
    assert!(err.to_string().contains("transition cost"), "{err}");
}
