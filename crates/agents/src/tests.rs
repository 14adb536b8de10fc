//! Behaviour tests of the agents: each learns a one-step task whose optimum is known, errors are
//! named, and checkpoints restore the exact numbers.

use rand::Rng as _;
use tandem_core::seeding::rng_from_seed;
use tandem_core::{Action, Space};
use tandem_nn::Checkpoint;

use crate::agent::{Agent, Episode, EpisodicAgent, Mode, OffPolicyAgent};
use crate::config::{Baseline, DdpgConfig, DqnConfig, ReinforceConfig, SacConfig};
use crate::replay::{ReplayBuffer, TransitionRef};
use crate::{AgentError, Ddpg, Dqn, NoiseConfig, Reinforce, Sac};

/// One-step continuous task: observation `s ~ U(-1, 1)`, actions in `[-2, 2]`, reward
/// `-(a - 1.5 s)²`; the optimal action is `1.5 s`.
fn continuous_bandit_buffer(n: usize, seed: u64) -> ReplayBuffer {
    let mut rng = rng_from_seed(seed);
    let mut b = ReplayBuffer::new(n, 1, 1).unwrap();
    for _ in 0..n {
        let s: f64 = rng.random_range(-1.0..1.0);
        let a: f64 = rng.random_range(-2.0..2.0);
        b.push(TransitionRef {
            obs: &[s],
            action: &[a],
            reward: -(a - 1.5 * s).powi(2),
            next_obs: &[0.0],
            terminated: true,
        })
        .unwrap();
    }
    b
}

fn mean_abs_error(agent: &mut dyn Agent) -> f64 {
    let pts: Vec<f64> = (0..21).map(|i| -0.9 + 0.09 * i as f64).collect();
    pts.iter()
        .map(|s| {
            let a = agent.act(&[*s], Mode::Deterministic).unwrap();
            (a.as_continuous().unwrap()[0] - 1.5 * s).abs()
        })
        .sum::<f64>()
        / pts.len() as f64
}

fn spaces() -> (Space, Space) {
    (Space::symmetric(1, 1.0), Space::symmetric(1, 2.0))
}

#[test]
fn ddpg_learns_the_optimal_action_of_a_one_step_task() {
    let (os, acts) = spaces();
    let cfg = DdpgConfig {
        actor_hidden: vec![64, 64],
        critic_hidden: vec![64, 64],
        actor_lr: 1e-3,
        critic_lr: 3e-3,
        tau: 0.05,
        batch_size: 64,
        ..DdpgConfig::default()
    };
    let mut agent = Ddpg::new(cfg, &os, &acts, 0).unwrap();
    let buf = continuous_bandit_buffer(4000, 1);
    let mut rng = rng_from_seed(2);
    let before = mean_abs_error(&mut agent);
    for _ in 0..1500 {
        let b = buf.sample(64, &mut rng).unwrap();
        agent.update(&b).unwrap();
    }
    let after = mean_abs_error(&mut agent);
    assert!(after < 0.15, "mean |a - a*| = {after} (before {before})");
}

/// The critic's L2 penalty shrinks its weights (against the same agent without it, on the
/// same minibatches) and, at the small value p0's authors use, still learns the task.
#[test]
fn ddpg_critic_weight_decay_shrinks_the_critic_and_still_learns() {
    let (os, acts) = spaces();
    let cfg = |critic_weight_decay| DdpgConfig {
        actor_hidden: vec![64, 64],
        critic_hidden: vec![64, 64],
        actor_lr: 1e-3,
        critic_lr: 3e-3,
        critic_weight_decay,
        tau: 0.05,
        batch_size: 64,
        ..DdpgConfig::default()
    };
    let buf = continuous_bandit_buffer(4000, 1);
    let norm = |p: &[f32]| p.iter().map(|&x| f64::from(x).powi(2)).sum::<f64>().sqrt();
    let mut norms = Vec::new();
    for wd in [0.0, 1e-3] {
        let mut agent = Ddpg::new(cfg(wd), &os, &acts, 0).unwrap();
        let mut rng = rng_from_seed(2);
        for _ in 0..1500 {
            agent.update(&buf.sample(64, &mut rng).unwrap()).unwrap();
        }
        norms.push(norm(agent.critic_params()));
        let err = mean_abs_error(&mut agent);
        assert!(err < 0.15, "weight decay {wd}: mean |a - a*| = {err}");
    }
    assert!(norms[1] < 0.99 * norms[0], "critic norms {norms:?}");
    let bad = cfg(-1e-3);
    let e = Ddpg::new(bad, &os, &acts, 0).unwrap_err();
    assert!(e.to_string().contains("critic_weight_decay"), "{e}");
}

#[test]
fn sac_learns_the_optimal_action_of_a_one_step_task() {
    let (os, acts) = spaces();
    let cfg = SacConfig {
        hidden: vec![64, 64],
        learning_rate: 3e-3,
        ..SacConfig::default()
    };
    let mut agent = Sac::new(cfg, &os, &acts, 0).unwrap();
    let buf = continuous_bandit_buffer(4000, 1);
    let mut rng = rng_from_seed(2);
    let before = mean_abs_error(&mut agent);
    let mut last = None;
    for _ in 0..1500 {
        let b = buf.sample(64, &mut rng).unwrap();
        last = Some(agent.update(&b).unwrap());
    }
    let after = mean_abs_error(&mut agent);
    assert!(after < 0.15, "mean |a - a*| = {after} (before {before})");
    // Automatic entropy tuning moved α away from its initial 1.
    assert!(agent.alpha() < 0.5, "alpha {}", agent.alpha());
    assert!(last.unwrap().get("critic_loss").unwrap().is_finite());
}

/// The actor gradient SAC feeds its network equals finite differences of the actor loss
/// `mean_i(α log π_i - w·a_i)` (a linear critic, so `dQ/da = w`), with the exact log-density
/// written out independently in f64.
#[test]
fn sac_actor_gradient_matches_finite_differences() {
    let (ad, n, alpha) = (2usize, 3usize, 0.7f32);
    let w = [0.8f64, -1.3];
    let mut rng = rng_from_seed(5);
    let out: Vec<f32> = (0..n * 2 * ad)
        .map(|k| {
            if k % (2 * ad) < ad {
                rng.random_range(-1.0..1.0)
            } else {
                rng.random_range(-1.5..0.5)
            }
        })
        .collect();
    let eps: Vec<f32> = (0..n * ad).map(|_| rng.random_range(-1.5..1.5)).collect();
    let loss = |o: &[f64]| -> f64 {
        let mut l = 0.0;
        for i in 0..n {
            for j in 0..ad {
                let (m, ls, e) = (
                    o[i * 2 * ad + j],
                    o[i * 2 * ad + ad + j],
                    f64::from(eps[i * ad + j]),
                );
                let u = m + ls.exp() * e;
                let a = u.tanh();
                let lp = -0.5 * e * e
                    - ls
                    - 0.5 * (2.0 * std::f64::consts::PI).ln()
                    - (1.0 - a * a).ln();
                l += f64::from(alpha) * lp - w[j] * a;
            }
        }
        l / n as f64
    };
    let head = tandem_nn::TanhGaussian::new(ad);
    let mut pi = tandem_nn::TanhGaussianSample::default();
    head.sample_with_noise(&out, n, &eps, &mut pi).unwrap();
    let dq: Vec<f32> = (0..n * ad).map(|k| w[k % ad] as f32).collect();
    let mut g = vec![0.0f32; n * 2 * ad];
    let mut scratch = (Vec::new(), Vec::new());
    Sac::actor_output_grad(
        &head,
        &pi,
        &dq,
        alpha,
        (&mut scratch.0, &mut scratch.1),
        &mut g,
    )
    .unwrap();
    let o64: Vec<f64> = out.iter().map(|v| f64::from(*v)).collect();
    for k in 0..o64.len() {
        let h = 1e-5;
        let (mut p, mut m) = (o64.clone(), o64.clone());
        p[k] += h;
        m[k] -= h;
        let fd = (loss(&p) - loss(&m)) / (2.0 * h);
        assert!(
            (fd - f64::from(g[k])).abs() < 2e-4 * (1.0 + fd.abs()),
            "component {k}: analytic {} vs finite difference {fd}",
            g[k]
        );
    }
}

/// stable-baselines3 semantics: ε and the target copy count environment steps
/// (`on_env_step`), not `act` calls or gradient steps.
#[test]
fn dqn_counts_epsilon_and_target_updates_in_env_steps() {
    let os = Space::symmetric(1, 1.0);
    let cfg = DqnConfig {
        hidden: vec![8],
        ..DqnConfig::default()
    };
    let mut agent = Dqn::new(cfg.clone(), &os, &Space::discrete(2), 0).unwrap();
    for _ in 0..50 {
        agent.act(&[0.3], Mode::Explore).unwrap();
    }
    assert_eq!(agent.epsilon(), 1.0, "act alone must not advance ε");
    for _ in 0..1000 {
        agent.on_env_step();
    }
    // SB3: 1 + (1000 / (0.16 · 50000)) · (0.04 - 1) = 0.88.
    assert!(
        (agent.epsilon() - 0.88).abs() < 1e-12,
        "{}",
        agent.epsilon()
    );
    assert_eq!(agent.q_params(), agent.target_params());
    let mut rng = rng_from_seed(1);
    let mut buf = ReplayBuffer::new(100, 1, 1).unwrap();
    for i in 0..100 {
        buf.push(TransitionRef {
            obs: &[f64::from(i) / 100.0],
            action: &[f64::from(i % 2)],
            reward: 1.0,
            next_obs: &[0.0],
            terminated: false,
        })
        .unwrap();
    }
    for _ in 0..(cfg.target_update_interval + 3) {
        agent.update(&buf.sample(16, &mut rng).unwrap()).unwrap();
    }
    assert_ne!(
        agent.q_params(),
        agent.target_params(),
        "gradient steps must not copy"
    );
    for _ in 0..(cfg.target_update_interval - 1) {
        agent.on_env_step();
        assert_ne!(agent.q_params(), agent.target_params());
    }
    agent.on_env_step();
    assert_eq!(agent.q_params(), agent.target_params());
}

/// Two actions, reward 1 for action `1{s > 0}`: the greedy policy must be right.
#[test]
fn dqn_learns_a_contextual_bandit_and_double_dqn_too() {
    for double in [false, true] {
        let os = Space::symmetric(1, 1.0);
        let cfg = DqnConfig {
            hidden: vec![32, 32],
            learning_rate: 3e-3,
            target_update_interval: 50,
            double_dqn: double,
            ..DqnConfig::default()
        };
        let mut agent = Dqn::new(cfg, &os, &Space::discrete(2), 0).unwrap();
        let mut rng = rng_from_seed(3);
        let mut buf = ReplayBuffer::new(2000, 1, 1).unwrap();
        for _ in 0..2000 {
            let s: f64 = rng.random_range(-1.0..1.0);
            let a = rng.random_range(0..2usize);
            let r = if (a == 1) == (s > 0.0) { 1.0 } else { 0.0 };
            buf.push(TransitionRef {
                obs: &[s],
                action: &[a as f64],
                reward: r,
                next_obs: &[0.0],
                terminated: true,
            })
            .unwrap();
        }
        for _ in 0..800 {
            agent.update(&buf.sample(64, &mut rng).unwrap()).unwrap();
        }
        let mut right = 0;
        for i in 0..40 {
            let s = -0.975 + 0.05 * i as f64;
            let a = agent.act(&[s], Mode::Deterministic).unwrap();
            if (a == Action::Discrete(1)) == (s > 0.0) {
                right += 1;
            }
        }
        assert!(
            right >= 38,
            "double={double}: {right}/40 greedy actions right"
        );
    }
}

#[cfg(feature = "pixels")]
mod conv {
    use super::*;
    use crate::config::QNetwork;
    use crate::conv_qnet::ConvQNetConfig;

    /// A 4×4 one-channel image with one lit pixel in the left or right half; reward 1 for the action
    /// naming the half (0 left, 1 right). The conv Q-network must learn to read the image.
    fn image_bandit_obs(rng: &mut tandem_core::Rng) -> (Vec<f64>, usize) {
        let (y, x) = (rng.random_range(0..4usize), rng.random_range(0..4usize));
        let mut img = vec![0.0; 16];
        img[y * 4 + x] = 1.0;
        (img, usize::from(x >= 2))
    }

    fn image_space() -> Space {
        Space::Box {
            low: vec![0.0; 16],
            high: vec![1.0; 16],
            shape: vec![4, 4, 1],
        }
    }

    fn conv_dqn_config() -> DqnConfig {
        DqnConfig {
            network: QNetwork::Conv,
            conv: ConvQNetConfig {
                image: [4, 4, 1],
                channels: vec![4],
                kernels: vec![3],
                strides: vec![1],
            },
            hidden: vec![16],
            learning_rate: 3e-3,
            target_update_interval: 50,
            ..DqnConfig::default()
        }
    }

    #[test]
    fn conv_dqn_learns_an_image_bandit_and_checkpoints_round_trip() {
        let mut agent =
            Dqn::new(conv_dqn_config(), &image_space(), &Space::discrete(2), 0).unwrap();
        let mut rng = rng_from_seed(5);
        let mut buf = ReplayBuffer::new(500, 16, 1).unwrap();
        for _ in 0..500 {
            let (img, right) = image_bandit_obs(&mut rng);
            let a = rng.random_range(0..2usize);
            buf.push(TransitionRef {
                obs: &img,
                action: &[a as f64],
                reward: if a == right { 1.0 } else { 0.0 },
                next_obs: &img,
                terminated: true,
            })
            .unwrap();
        }
        for _ in 0..300 {
            agent.update(&buf.sample(32, &mut rng).unwrap()).unwrap();
        }
        // Every one of the 16 images: greedy action right, Q of the right action near 1.
        for k in 0..16 {
            let mut img = vec![0.0; 16];
            img[k] = 1.0;
            let right = usize::from(k % 4 >= 2);
            assert_eq!(
                agent.act(&img, Mode::Deterministic).unwrap(),
                Action::Discrete(right),
                "pixel {k}"
            );
            let q = agent.q_values(&img).unwrap();
            assert!((q[right] - 1.0).abs() < 0.2, "pixel {k}: {q:?}");
        }

        // Save, keep training the original, load into a fresh agent and train it the same way.
        let mut ckpt = Checkpoint::new();
        agent.save(&mut ckpt).unwrap();
        let ckpt = Checkpoint::from_bytes(&ckpt.to_bytes().unwrap()).unwrap();
        let mut other =
            Dqn::new(conv_dqn_config(), &image_space(), &Space::discrete(2), 9).unwrap();
        other.load(&ckpt).unwrap();
        assert_eq!(other.q_params(), agent.q_params());
        assert_eq!(other.target_params(), agent.target_params());
        let batch = buf.sample(32, &mut rng).unwrap();
        for _ in 0..3 {
            agent.update(&batch).unwrap();
            other.update(&batch).unwrap();
        }
        assert_eq!(
            other.q_params(),
            agent.q_params(),
            "Adam state not restored"
        );
        let (mut a, mut b) = (agent.clone(), other.clone());
        for _ in 0..20 {
            assert_eq!(
                a.act(&batch.obs.row(0).mapv(f64::from).to_vec(), Mode::Explore)
                    .unwrap(),
                b.act(&batch.obs.row(0).mapv(f64::from).to_vec(), Mode::Explore)
                    .unwrap()
            );
        }

        // An MLP DQN checkpoint does not load into the conv agent, and vice versa.
        let mlp_cfg = DqnConfig {
            hidden: vec![16],
            ..DqnConfig::default()
        };
        let mut mlp = Dqn::new(mlp_cfg, &image_space(), &Space::discrete(2), 0).unwrap();
        let e = mlp.load(&ckpt).unwrap_err();
        assert!(matches!(e, AgentError::Checkpoint(_)), "{e}");
        let mut mlp_ck = Checkpoint::new();
        mlp.save(&mut mlp_ck).unwrap();
        let before = other.q_params().to_vec();
        let e = other.load(&mlp_ck).unwrap_err();
        assert!(e.to_string().contains("conv"), "{e}");
        assert_eq!(other.q_params(), &before[..]);
    }

    #[test]
    fn conv_dqn_is_seeded_and_rejects_observations_that_are_not_its_image() {
        let acts = Space::discrete(2);
        let a = Dqn::new(conv_dqn_config(), &image_space(), &acts, 3).unwrap();
        let b = Dqn::new(conv_dqn_config(), &image_space(), &acts, 3).unwrap();
        let c = Dqn::new(conv_dqn_config(), &image_space(), &acts, 4).unwrap();
        assert_eq!(a.q_params(), b.q_params());
        assert_eq!(a.q_params(), a.target_params());
        assert_ne!(a.q_params(), c.q_params());
        // A flat vector of the right length, an image of another shape, a discrete space.
        for space in [
            Space::symmetric(16, 1.0),
            Space::Box {
                low: vec![0.0; 16],
                high: vec![1.0; 16],
                shape: vec![2, 8, 1],
            },
        ] {
            let e = Dqn::new(conv_dqn_config(), &space, &acts, 0).unwrap_err();
            assert!(
                matches!(e, AgentError::WrongObservationSpace { agent: "dqn", .. }),
                "{e}"
            );
            assert!(e.to_string().contains("[4, 4, 1]"), "{e}");
        }
        assert!(Dqn::new(conv_dqn_config(), &Space::discrete(3), &acts, 0).is_err());
        // A conv layer list out of range is a config error.
        let bad = DqnConfig {
            conv: ConvQNetConfig {
                kernels: vec![2],
                ..conv_dqn_config().conv
            },
            ..conv_dqn_config()
        };
        assert!(matches!(
            Dqn::new(bad, &image_space(), &acts, 0),
            Err(AgentError::Config { .. })
        ));
        // An observation of the wrong length when acting.
        let mut a = a;
        assert!(matches!(
            a.act(&[0.0; 15], Mode::Deterministic),
            Err(AgentError::Dim { .. })
        ));
    }
}

#[test]
fn dqn_learning_rate_decays_linearly_in_env_steps() {
    let cfg = DqnConfig {
        hidden: vec![8],
        learning_rate: 1e-3,
        learning_rate_final: Some(1e-4),
        learning_rate_decay_steps: 1000,
        ..DqnConfig::default()
    };
    let mut agent = Dqn::new(
        cfg.clone(),
        &Space::symmetric(1, 1.0),
        &Space::discrete(2),
        0,
    )
    .unwrap();
    assert_eq!(agent.learning_rate(), 1e-3);
    for _ in 0..500 {
        agent.on_env_step();
    }
    assert!((agent.learning_rate() - 5.5e-4).abs() < 1e-12);
    for _ in 0..1500 {
        agent.on_env_step();
    }
    assert!((agent.learning_rate() - 1e-4).abs() < 1e-15);
    assert_eq!(DqnConfig::default().learning_rate_at(10_000), 2.3e-3);
    for bad in [Some(2e-3), Some(-1.0), Some(f64::NAN)] {
        let c = DqnConfig {
            learning_rate_final: bad,
            ..cfg.clone()
        };
        assert!(
            matches!(c.validate(), Err(AgentError::Config { .. })),
            "{bad:?}"
        );
    }
}

#[test]
fn reinforce_learns_a_contextual_bandit_with_each_baseline() {
    for baseline in [Baseline::None, Baseline::Normalize, Baseline::Value] {
        let cfg = ReinforceConfig {
            hidden: vec![8],
            learning_rate: 2e-2,
            baseline,
            ..ReinforceConfig::default()
        };
        let os = Space::symmetric(1, 1.0);
        let mut agent = Reinforce::new(cfg, &os, &Space::discrete(2), 0).unwrap();
        let mut rng = rng_from_seed(4);
        for _ in 0..300 {
            let eps: Vec<Episode> = (0..16)
                .map(|_| {
                    let s: f64 = rng.random_range(-1.0..1.0);
                    let a = agent.act(&[s], Mode::Explore).unwrap();
                    let r = if (a == Action::Discrete(1)) == (s > 0.0) {
                        1.0
                    } else {
                        0.0
                    };
                    let mut e = Episode::default();
                    e.push(vec![s], a, r);
                    e.terminated = true;
                    e
                })
                .collect();
            agent.update(&eps).unwrap();
        }
        let p_right = (0..20)
            .map(|i| {
                let s = -0.95 + 0.1 * i as f64;
                let p = agent.probabilities(&[s]).unwrap();
                f64::from(if s > 0.0 { p[1] } else { p[0] })
            })
            .sum::<f64>()
            / 20.0;
        assert!(
            p_right > 0.85,
            "{baseline:?}: mean probability of the right action {p_right}"
        );
    }
}

#[test]
fn wrong_action_spaces_are_named_errors() {
    let os = Space::symmetric(3, 1.0);
    let e = Sac::new(SacConfig::default(), &os, &Space::discrete(2), 0).unwrap_err();
    assert!(matches!(
        e,
        AgentError::WrongActionSpace { agent: "sac", .. }
    ));
    assert!(e.to_string().contains("Discrete(2)"), "{e}");
    let e = Ddpg::new(
        DdpgConfig::default(),
        &os,
        &Space::symmetric(1, f64::INFINITY),
        0,
    );
    assert!(matches!(
        e,
        Err(AgentError::WrongActionSpace { agent: "ddpg", .. })
    ));
    let e = Dqn::new(DqnConfig::default(), &os, &Space::symmetric(1, 1.0), 0);
    assert!(matches!(
        e,
        Err(AgentError::WrongActionSpace { agent: "dqn", .. })
    ));
    let e = Reinforce::new(
        ReinforceConfig::default(),
        &os,
        &Space::symmetric(1, 1.0),
        0,
    );
    assert!(matches!(
        e,
        Err(AgentError::WrongActionSpace {
            agent: "reinforce",
            ..
        })
    ));
    let e = Sac::new(
        SacConfig::default(),
        &Space::discrete(4),
        &Space::symmetric(1, 1.0),
        0,
    );
    assert!(matches!(e, Err(AgentError::WrongObservationSpace { .. })));
    // Bad observations at act time.
    let mut sac = Sac::new(SacConfig::default(), &os, &Space::symmetric(1, 1.0), 0).unwrap();
    assert!(matches!(
        sac.act(&[0.0, 0.0], Mode::Explore),
        Err(AgentError::Dim {
            expected: 3,
            got: 2,
            ..
        })
    ));
    assert!(matches!(
        sac.act(&[0.0, f64::NAN, 0.0], Mode::Explore),
        Err(AgentError::NonFinite { .. })
    ));
    // Out-of-range config.
    let bad = SacConfig {
        gamma: 1.5,
        ..SacConfig::default()
    };
    let e = Sac::new(bad, &os, &Space::symmetric(1, 1.0), 0).unwrap_err();
    assert!(e.to_string().contains("gamma"), "{e}");
    let bad = DdpgConfig {
        noise: NoiseConfig::Gaussian { sigma: -0.1 },
        ..DdpgConfig::default()
    };
    assert!(matches!(
        Ddpg::new(bad, &os, &Space::symmetric(1, 1.0), 0),
        Err(AgentError::Config { .. })
    ));
}

#[test]
fn checkpoints_restore_exact_numbers_and_reject_other_architectures() {
    let (os, acts) = spaces();
    let small = SacConfig {
        hidden: vec![16, 16],
        ..SacConfig::default()
    };
    let buf = continuous_bandit_buffer(256, 1);
    let mut rng = rng_from_seed(9);
    let mut a = Sac::new(small.clone(), &os, &acts, 1).unwrap();
    for _ in 0..5 {
        a.update(&buf.sample(32, &mut rng).unwrap()).unwrap();
    }
    let mut ckpt = Checkpoint::new();
    a.save(&mut ckpt).unwrap();
    let bytes = ckpt.to_bytes().unwrap();
    let mut b = Sac::new(small.clone(), &os, &acts, 777).unwrap();
    b.load(&Checkpoint::from_bytes(&bytes).unwrap()).unwrap();
    for _ in 0..3 {
        let batch = buf.sample(32, &mut rng).unwrap();
        assert_eq!(a.update(&batch).unwrap(), b.update(&batch).unwrap());
        assert_eq!(
            a.act(&[0.3], Mode::Explore).unwrap(),
            b.act(&[0.3], Mode::Explore).unwrap()
        );
    }
    assert_eq!(a.actor_params(), b.actor_params());

    // Another architecture or another algorithm: named errors.
    let wide = SacConfig {
        hidden: vec![32, 16],
        ..SacConfig::default()
    };
    let mut c = Sac::new(wide, &os, &acts, 0).unwrap();
    let e = c.load(&ckpt).unwrap_err();
    assert!(matches!(e, AgentError::Checkpoint(_)), "{e}");
    assert!(e.to_string().contains("architecture"), "{e}");
    let mut d = Ddpg::new(DdpgConfig::default(), &os, &acts, 0).unwrap();
    let e = d.load(&ckpt).unwrap_err();
    assert!(e.to_string().contains("`sac`"), "{e}");
    let mut q = Dqn::new(DqnConfig::default(), &os, &Space::discrete(3), 0).unwrap();
    let e = q.load(&ckpt).unwrap_err();
    assert!(matches!(e, AgentError::Checkpoint(_)), "{e}");
}

mod batch {
    //! The `&self` batch API ([`BatchPolicy`], [`Critic`]) against the single-row path and
    //! against independent computations from the networks' outputs.

    use ndarray::{Array2, ArrayView2};
    use rand::Rng as _;
    use tandem_core::seeding::rng_from_seed;
    use tandem_core::{Rng, Space};

    use crate::agent::{Agent, BatchPolicy, Critic, Mode};
    use crate::config::{DdpgConfig, DqnConfig, ReinforceConfig, SacConfig};
    use crate::{Ddpg, Dqn, NoiseConfig, Reinforce, Sac};

    const OD: usize = 3;

    fn obs_batch(b: usize, seed: u64) -> Array2<f64> {
        let mut rng = rng_from_seed(seed);
        Array2::from_shape_fn((b, OD), |_| rng.random_range(-1.0..1.0))
    }

    /// `b` copies of one observation.
    fn repeated(b: usize) -> Array2<f64> {
        Array2::from_shape_fn((b, OD), |(_, j)| [0.3, -0.6, 0.1][j])
    }

    fn box_spaces(ad: usize) -> (Space, Space) {
        (
            Space::symmetric(OD, 1.0),
            Space::boxed(vec![-2.0; ad], vec![3.0; ad]),
        )
    }

    fn sac() -> Sac {
        let (o, a) = box_spaces(2);
        let cfg = SacConfig {
            hidden: vec![32, 32],
            ..SacConfig::default()
        };
        Sac::new(cfg, &o, &a, 11).unwrap()
    }

    fn ddpg(noise: NoiseConfig) -> Ddpg {
        let (o, a) = box_spaces(2);
        let cfg = DdpgConfig {
            actor_hidden: vec![32, 32],
            critic_hidden: vec![32, 32],
            noise,
            ..DdpgConfig::default()
        };
        Ddpg::new(cfg, &o, &a, 12).unwrap()
    }

    fn dqn() -> Dqn {
        let cfg = DqnConfig {
            hidden: vec![32, 32],
            ..DqnConfig::default()
        };
        Dqn::new(cfg, &Space::symmetric(OD, 1.0), &Space::discrete(4), 13).unwrap()
    }

    fn reinforce() -> Reinforce {
        let cfg = ReinforceConfig {
            hidden: vec![32],
            ..ReinforceConfig::default()
        };
        Reinforce::new(cfg, &Space::symmetric(OD, 1.0), &Space::discrete(3), 14).unwrap()
    }

    /// Deterministic batch rows equal the single-row `act` of each row (f32 networks: 1e-6
    /// relative; a batch of 7 may take other gemm kernels than a batch of 1).
    fn assert_rows_match_act(agent: &mut (impl Agent + BatchPolicy)) {
        let obs = obs_batch(7, 1);
        let mut rng = rng_from_seed(0);
        let batch = agent
            .act_batch(obs.view(), Mode::Deterministic, &mut rng)
            .unwrap();
        let rows = agent
            .act_rows(obs.view(), Mode::Deterministic, &mut rng)
            .unwrap();
        assert_eq!(batch.nrows(), 7);
        for (i, o) in obs.rows().into_iter().enumerate() {
            let single = agent
                .act(o.as_slice().unwrap(), Mode::Deterministic)
                .unwrap();
            assert_eq!(rows[i], single.clone());
            let want: Vec<f64> = match single {
                tandem_core::Action::Continuous(v) => v,
                tandem_core::Action::Discrete(k) => vec![k as f64],
            };
            for (g, w) in batch.row(i).iter().zip(&want) {
                assert!(
                    (g - w).abs() <= 1e-6 * (1.0 + w.abs()),
                    "row {i}: {g} vs {w}"
                );
            }
        }
    }

    #[test]
    fn deterministic_batches_equal_row_by_row_acting() {
        assert_rows_match_act(&mut sac());
        assert_rows_match_act(&mut ddpg(NoiseConfig::default()));
        assert_rows_match_act(&mut dqn());
        assert_rows_match_act(&mut reinforce());
    }

    #[test]
    fn agents_are_usable_as_trait_objects_and_explore_reproducibly() {
        let (s, d, q, r) = (sac(), ddpg(NoiseConfig::default()), dqn(), reinforce());
        let policies: [&dyn BatchPolicy; 4] = [&s, &d, &q, &r];
        let obs = obs_batch(5, 2);
        for p in policies {
            let a = p
                .act_batch(obs.view(), Mode::Explore, &mut rng_from_seed(3))
                .unwrap();
            let b = p
                .act_batch(obs.view(), Mode::Explore, &mut rng_from_seed(3))
                .unwrap();
            assert_eq!(a, b);
            assert_eq!(a.dim(), (5, p.action_width()));
        }
        let critics: [&dyn Critic; 3] = [&s, &d, &q];
        for c in critics {
            let v1 = c
                .v_batch(obs.view(), Mode::Explore, &mut rng_from_seed(4))
                .unwrap();
            let v2 = c
                .v_batch(obs.view(), Mode::Explore, &mut rng_from_seed(4))
                .unwrap();
            assert_eq!(v1, v2);
            assert!(v1.iter().all(|v| v.is_finite()));
        }
    }

    /// `[mean | log-std]` of SAC's actor for the rows of `obs`, in f64.
    fn sac_actor_out(agent: &Sac, obs: ArrayView2<'_, f64>) -> Vec<f64> {
        let x: Vec<f32> = obs.iter().map(|v| *v as f32).collect();
        let out = agent.actor.infer(&x, obs.nrows()).unwrap();
        out.iter().map(|v| f64::from(*v)).collect()
    }

    /// Environment actions (box [-2, 3]) back to `[-1, 1]`.
    fn unscale(a: f64) -> f64 {
        (a - 0.5) / 2.5
    }

    #[test]
    fn sac_samples_have_the_policy_mean_and_std_before_the_squash() {
        let agent = sac();
        let b = 20_000;
        let obs = repeated(b);
        let out = sac_actor_out(&agent, obs.slice(ndarray::s![0..1, ..]));
        let a = agent
            .act_batch(obs.view(), Mode::Explore, &mut rng_from_seed(9))
            .unwrap();
        for j in 0..2 {
            let u: Vec<f64> = a.column(j).iter().map(|v| unscale(*v).atanh()).collect();
            let mean = u.iter().sum::<f64>() / b as f64;
            let sd = (u.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / b as f64).sqrt();
            let (mu, sigma) = (out[j], out[2 + j].clamp(-20.0, 2.0).exp());
            // Standard errors: sigma / sqrt(b) for the mean, sigma / sqrt(2b) for the std.
            assert!(
                (mean - mu).abs() < 4.0 * sigma / (b as f64).sqrt(),
                "{mean} vs {mu}"
            );
            assert!(
                (sd - sigma).abs() < 4.0 * sigma / (2.0 * b as f64).sqrt(),
                "{sd} vs {sigma}"
            );
        }
    }

    /// `log π(a|s)` of actions in `[-1, 1]` from the actor's output, written out in f64: the
    /// Gaussian density of `u = atanh a` minus `log(1 - a²)`.
    fn log_pi(out: &[f64], a: &[f64]) -> f64 {
        let ad = a.len();
        (0..ad)
            .map(|j| {
                let ls = out[ad + j].clamp(-20.0, 2.0);
                let z = (a[j].atanh() - out[j]) / ls.exp();
                -0.5 * z * z
                    - ls
                    - 0.5 * (2.0 * std::f64::consts::PI).ln()
                    - (1.0 - a[j] * a[j]).ln()
            })
            .sum()
    }

    #[test]
    fn sac_soft_value_matches_its_q_nets_and_log_probs() {
        let agent = sac();
        let obs = obs_batch(6, 5);
        let out = sac_actor_out(&agent, obs.view());
        let alpha = agent.alpha();
        // Deterministic: at the mean action tanh(μ).
        let mean_a = Array2::from_shape_fn((6, 2), |(i, j)| 0.5 + 2.5 * out[i * 4 + j].tanh());
        let q = agent.q_batch(obs.view(), mean_a.view()).unwrap();
        let v = agent
            .v_batch(obs.view(), Mode::Deterministic, &mut rng_from_seed(0))
            .unwrap();
        for i in 0..6 {
            let a: Vec<f64> = (0..2).map(|j| out[i * 4 + j].tanh()).collect();
            let want = q[i] - alpha * log_pi(&out[i * 4..i * 4 + 4], &a);
            assert!(
                (v[i] - want).abs() < 1e-4 * (1.0 + want.abs()),
                "{} vs {want}",
                v[i]
            );
        }
        // Explore: the action act_batch draws with the same generator state.
        let a = agent
            .act_batch(obs.view(), Mode::Explore, &mut rng_from_seed(8))
            .unwrap();
        let q = agent.q_batch(obs.view(), a.view()).unwrap();
        let v = agent
            .v_batch(obs.view(), Mode::Explore, &mut rng_from_seed(8))
            .unwrap();
        for i in 0..6 {
            let an: Vec<f64> = a.row(i).iter().map(|x| unscale(*x)).collect();
            let want = q[i] - alpha * log_pi(&out[i * 4..i * 4 + 4], &an);
            assert!(
                (v[i] - want).abs() < 1e-3 * (1.0 + want.abs()),
                "{} vs {want}",
                v[i]
            );
        }
        // Q is the smaller twin: never above either critic's own value.
        let x: Vec<f32> = obs.iter().map(|v| *v as f32).collect();
        let an: Vec<f32> = a.iter().map(|v| unscale(*v) as f32).collect();
        let mut xa = vec![0.0; 6 * 5];
        crate::common::concat_rows(&x, 3, &an, 2, &mut xa);
        let (q1, q2) = (
            agent.q1.infer(&xa, 6).unwrap(),
            agent.q2.infer(&xa, 6).unwrap(),
        );
        for i in 0..6 {
            assert!((q[i] - f64::from(q1[i].min(q2[i]))).abs() < 1e-5 * (1.0 + q[i].abs()));
        }
    }

    #[test]
    fn ddpg_value_is_q_at_the_policy_action_and_explores_with_its_noise() {
        let mut agent = ddpg(NoiseConfig::default());
        let obs = obs_batch(6, 6);
        let mut rng = rng_from_seed(0);
        let mu = agent
            .act_batch(obs.view(), Mode::Deterministic, &mut rng)
            .unwrap();
        let q = agent.q_batch(obs.view(), mu.view()).unwrap();
        let v = agent.v_batch(obs.view(), Mode::Explore, &mut rng).unwrap();
        for i in 0..6 {
            assert!(
                (v[i] - q[i]).abs() < 1e-5 * (1.0 + q[i].abs()),
                "{} vs {}",
                v[i],
                q[i]
            );
        }
        // Gaussian noise σ = 0.1 (in [-1, 1] units) set between phases: the batch's deviations
        // from μ(s) have that std, and so does the OU default's stationary std.
        for noise in [NoiseConfig::Gaussian { sigma: 0.1 }, NoiseConfig::default()] {
            agent.set_noise(noise).unwrap();
            assert_eq!(agent.noise(), noise);
            let b = 20_000;
            let obs = repeated(b);
            let mu = agent
                .act_batch(obs.view(), Mode::Deterministic, &mut rng)
                .unwrap();
            let a = agent
                .act_batch(obs.view(), Mode::Explore, &mut rng)
                .unwrap();
            let d: Vec<f64> = (0..b).map(|i| (a[[i, 0]] - mu[[i, 0]]) / 2.5).collect();
            let mean = d.iter().sum::<f64>() / b as f64;
            let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / b as f64).sqrt();
            let want = noise.stationary_std();
            assert!(mean.abs() < 4.0 * want / (b as f64).sqrt(), "{mean}");
            assert!((sd / want - 1.0).abs() < 0.03, "{sd} vs {want}");
        }
        assert!(agent
            .set_noise(NoiseConfig::Gaussian { sigma: -1.0 })
            .is_err());
        assert_eq!(agent.noise(), NoiseConfig::default());
    }

    #[test]
    fn dqn_q_table_argmax_is_the_greedy_action_and_explores_epsilon_greedily() {
        let agent = dqn();
        let obs = obs_batch(8, 7);
        let mut rng = rng_from_seed(0);
        let q = agent.q_table(obs.view()).unwrap();
        let greedy = agent
            .act_indices(obs.view(), Mode::Deterministic, &mut rng)
            .unwrap();
        let v = agent
            .v_batch(obs.view(), Mode::Deterministic, &mut rng)
            .unwrap();
        let col = Array2::from_shape_fn((8, 1), |(i, _)| greedy[i] as f64);
        let q_sa = agent.q_batch(obs.view(), col.view()).unwrap();
        for i in 0..8 {
            let row = q.row(i);
            assert!(row.iter().all(|x| *x <= row[greedy[i]]));
            assert_eq!(q_sa[i], row[greedy[i]]);
            assert_eq!(v[i], row[greedy[i]]);
        }
        // ε-greedy: the greedy action with probability 1 - ε + ε/4.
        let mut agent = agent;
        for _ in 0..6000 {
            agent.on_env_step();
        }
        let eps = agent.epsilon();
        assert!(eps > 0.2 && eps < 0.8, "{eps}");
        let b = 20_000;
        let obs = repeated(b);
        let g = agent.act_indices(
            obs.slice(ndarray::s![0..1, ..]),
            Mode::Deterministic,
            &mut rng,
        );
        let k = agent
            .act_indices(obs.view(), Mode::Explore, &mut rng)
            .unwrap();
        let f = k.iter().filter(|x| **x == g.as_ref().unwrap()[0]).count() as f64 / b as f64;
        let want = 1.0 - eps + eps / 4.0;
        assert!(
            (f - want).abs() < 4.0 * (want * (1.0 - want) / b as f64).sqrt(),
            "{f} vs {want}"
        );
    }

    #[test]
    fn reinforce_samples_with_its_softmax_probabilities() {
        let mut agent = reinforce();
        let b = 30_000;
        let obs = repeated(b);
        let p = agent.probabilities(obs.row(0).as_slice().unwrap()).unwrap();
        let k = agent
            .act_indices(obs.view(), Mode::Explore, &mut rng_from_seed(2))
            .unwrap();
        for (j, pj) in p.iter().enumerate() {
            let f = k.iter().filter(|x| **x == j).count() as f64 / b as f64;
            let pj = f64::from(*pj);
            assert!(
                (f - pj).abs() < 4.0 * (pj * (1.0 - pj) / b as f64).sqrt(),
                "{f} vs {pj}"
            );
        }
    }

    #[test]
    fn bad_batches_are_named_errors() {
        let (s, q) = (sac(), dqn());
        let mut rng: Rng = rng_from_seed(0);
        let wide = Array2::<f64>::zeros((2, OD + 1));
        assert!(s.act_batch(wide.view(), Mode::Explore, &mut rng).is_err());
        let empty = Array2::<f64>::zeros((0, OD));
        assert!(q.act_batch(empty.view(), Mode::Explore, &mut rng).is_err());
        let mut nan = Array2::<f64>::zeros((2, OD));
        nan[[1, 2]] = f64::NAN;
        assert!(s
            .v_batch(nan.view(), Mode::Deterministic, &mut rng)
            .is_err());
        let obs = Array2::<f64>::zeros((2, OD));
        assert!(s.q_batch(obs.view(), Array2::zeros((3, 2)).view()).is_err());
        for bad in [4.0, -1.0, 0.5, f64::NAN] {
            let a = Array2::from_elem((2, 1), bad);
            assert!(q.q_batch(obs.view(), a.view()).is_err(), "{bad}");
        }
    }
}
