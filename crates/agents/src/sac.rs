//! SAC (Haarnoja et al. 2018) with twin critics, target critics, automatic entropy tuning and a
//! tanh-squashed Gaussian actor, following stable-baselines3's `SAC.train` step by step.
//!
//! The actor outputs `[mean, log_std]` and `tandem-nn`'s [`TanhGaussian`] head turns them into
//! actions and log-probabilities: log-std clamped to `[log_std_min, log_std_max]` (zero gradient
//! outside, as `torch.clamp`), `a = tanh(u)`, `u = mean + std ε`, `ε ~ N(0, I)` from the agent's
//! own seeded generator, with the exact change of variables
//! `log π(a|s) = Σ_j [-ε_j²/2 - log_std_j - log(2π)/2 - log(1 - tanh² u_j)]` (stable form; SB3
//! writes `log(1 - a² + 1e-6)`, which differs by at most `1e-6 / (1 - a²)` per component).
//!
//! The actor gradient is the head's reparametrized backward: with
//! `L = mean_i(α log π_i - min(Q1, Q2)(s_i, a_i))`, `dL/da = -dQmin/da / n` (the input gradient
//! of whichever critic is smaller for that row) and `dL/dlog π = α / n`. Tested against finite
//! differences.
//!
//! Acting and critic values through `&self` ([`BatchPolicy`], [`Critic`]) use the caller's
//! generator; [`Agent::act`] is the one-row case of [`BatchPolicy::act_batch`] drawn from the
//! agent's own stream.

use ndarray::{Array1, Array2, ArrayView2};
use tandem_core::{Action, Rng, SeedStream, Space};
use tandem_nn::{
    Adam, AdamConfig, Checkpoint, Checkpointable, MlpConfig, MlpWorkspace, Optimizer, TanhGaussian,
    TanhGaussianSample,
};

use crate::agent::{
    act_one_row, check_action_rows, obs_rows, Agent, Batch, BatchPolicy, Critic, Metrics, Mode,
    OffPolicyAgent,
};
use crate::common::{
    check_header, concat_rows, fit, obs_dim, save_header, ActionScale, Net, Target,
};
use crate::config::SacConfig;
use crate::error::{AgentError, Result};

/// A SAC agent.
#[derive(Debug, Clone)]
pub struct Sac {
    config: SacConfig,
    od: usize,
    scale: ActionScale,
    head: TanhGaussian,
    pub(crate) actor: Net,
    pub(crate) q1: Net,
    pub(crate) q2: Net,
    q1_t: Target,
    q2_t: Target,
    log_alpha: [f32; 1],
    alpha_opt: Adam,
    target_entropy: f32,
    rng: Rng,
    next_ws: MlpWorkspace,
    s: Scratch,
}

#[derive(Debug, Clone, Default)]
struct Scratch {
    a_norm: Vec<f32>,
    x: Vec<f32>,
    y: Vec<f32>,
    d_q: Vec<f32>,
    d_q2: Vec<f32>,
    d_x: Vec<f32>,
    d_x2: Vec<f32>,
    d_out: Vec<f32>,
    d_a: Vec<f32>,
    dq_da: Vec<f32>,
    d_logp: Vec<f32>,
    actor_out: Vec<f32>,
    next_out: Vec<f32>,
    pi: TanhGaussianSample,
    pi_next: TanhGaussianSample,
    q_pi1: Vec<f32>,
    q_pi2: Vec<f32>,
}

impl Sac {
    /// A SAC agent for the given spaces (a bounded box action space), seeded by `seed`.
    pub fn new(config: SacConfig, obs_space: &Space, act_space: &Space, seed: u64) -> Result<Self> {
        config.validate()?;
        let od = obs_dim("sac", obs_space)?;
        let scale = ActionScale::new("sac", act_space)?;
        let ad = scale.dim();
        config
            .memory(od, ad)
            .check(&format!("sac (obs {od}, act {ad})"))?;
        let seeds = SeedStream::new(seed);
        let mut init = seeds.rng("sac-init");
        let mut sizes = vec![od];
        sizes.extend(&config.hidden);
        sizes.push(2 * ad);
        let actor = Net::new(MlpConfig::new(&sizes), config.learning_rate, &mut init)?;
        let mut sizes = vec![od + ad];
        sizes.extend(&config.hidden);
        sizes.push(1);
        let q1 = Net::new(MlpConfig::new(&sizes), config.learning_rate, &mut init)?;
        let q2 = Net::new(MlpConfig::new(&sizes), config.learning_rate, &mut init)?;
        let alpha_opt = Adam::new(AdamConfig::with_lr(config.learning_rate as f32), 1)?;
        let head = TanhGaussian {
            dim: ad,
            log_std_min: config.log_std_min as f32,
            log_std_max: config.log_std_max as f32,
        };
        Ok(Self {
            head,
            q1_t: Target::of(&q1),
            q2_t: Target::of(&q2),
            log_alpha: [config.init_alpha.ln() as f32],
            alpha_opt,
            target_entropy: config.target_entropy.unwrap_or(-(ad as f64)) as f32,
            rng: seeds.rng("sac-sample"),
            config,
            od,
            scale,
            actor,
            q1,
            q2,
            next_ws: MlpWorkspace::default(),
            s: Scratch::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &SacConfig {
        &self.config
    }

    /// The current entropy coefficient α.
    pub fn alpha(&self) -> f64 {
        f64::from(self.log_alpha[0]).exp()
    }

    /// The actor's flat parameters.
    pub fn actor_params(&self) -> &[f32] {
        self.actor.mlp.params()
    }

    /// Stores networks, optimizer states, α and generator.
    pub fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
        save_header(
            ckpt,
            "sac",
            &self.config,
            (self.od, self.scale.dim()),
            &self.rng,
        )?;
        self.actor.save("actor", ckpt)?;
        self.q1.save("critic1", ckpt)?;
        self.q2.save("critic2", ckpt)?;
        self.q1_t.save("critic1_target", ckpt)?;
        self.q2_t.save("critic2_target", ckpt)?;
        ckpt.put_f32("log_alpha", &[1], &self.log_alpha)?;
        self.alpha_opt.save_to("log_alpha_opt", ckpt)?;
        Ok(())
    }

    /// Restores what [`Sac::save`] stored; errors for another algorithm or architecture.
    pub fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
        let rng = check_header(ckpt, "sac", (self.od, self.scale.dim()))?;
        self.actor.load("actor", ckpt)?;
        self.q1.load("critic1", ckpt)?;
        self.q2.load("critic2", ckpt)?;
        self.q1_t.load("critic1_target", ckpt)?;
        self.q2_t.load("critic2_target", ckpt)?;
        ckpt.read_f32_into("log_alpha", &[1], &mut self.log_alpha)?;
        self.alpha_opt.load_from("log_alpha_opt", ckpt)?;
        self.rng = rng;
        Ok(())
    }

    /// The actor loss's gradient wrt the actor outputs (`n x 2ad`) for the sample `pi` and
    /// `dQmin/da` (`n x ad`): the head's backward with `dL/da = -dQmin/da / n` and
    /// `dL/dlog π = α / n`. `d_a` and `d_logp` are scratch.
    pub(crate) fn actor_output_grad(
        head: &TanhGaussian,
        pi: &TanhGaussianSample,
        dq_da: &[f32],
        alpha: f32,
        (d_a, d_logp): (&mut Vec<f32>, &mut Vec<f32>),
        d_out: &mut [f32],
    ) -> Result<()> {
        let n = pi.batch();
        let inv_n = 1.0 / n as f32;
        d_a.clear();
        d_a.extend(dq_da.iter().map(|g| -g * inv_n));
        d_logp.clear();
        d_logp.resize(n, alpha * inv_n);
        head.backward(pi, Some(d_a), Some(d_logp), d_out)?;
        Ok(())
    }

    /// The policy at the rows of `obs`: actions in `[-1, 1]` and their log-probabilities. Explore
    /// samples with noise from `rng`; Deterministic takes the mean (`ε = 0`, no draw).
    fn policy(
        &self,
        obs: ArrayView2<'_, f64>,
        mode: Mode,
        rng: &mut Rng,
    ) -> Result<(Vec<f32>, TanhGaussianSample)> {
        let (x, out) = self.actor.infer_obs(obs, self.od)?;
        let n = obs.nrows();
        let mut pi = TanhGaussianSample::default();
        match mode {
            Mode::Explore => self.head.sample(&out, n, rng, &mut pi)?,
            Mode::Deterministic => {
                let zeros = vec![0.0; n * self.head.dim];
                self.head.sample_with_noise(&out, n, &zeros, &mut pi)?
            }
        }
        Ok((x, pi))
    }

    /// `min(Q1, Q2)(s, a)` of the online critics for row-major `f32` observations and actions in
    /// `[-1, 1]`.
    fn min_q(&self, x: &[f32], a: &[f32], n: usize) -> Result<Vec<f32>> {
        let mut xa = vec![0.0; n * (self.od + self.head.dim)];
        concat_rows(x, self.od, a, self.head.dim, &mut xa);
        let (q1, q2) = (self.q1.infer(&xa, n)?, self.q2.infer(&xa, n)?);
        Ok(q1.iter().zip(&q2).map(|(a, b)| a.min(*b)).collect())
    }
}

impl BatchPolicy for Sac {
    fn obs_dim(&self) -> usize {
        self.od
    }

    fn action_width(&self) -> usize {
        self.scale.dim()
    }

    /// Explore: `a = tanh(μ + σε)` with `ε` from `rng` (row by row); Deterministic: `tanh(μ)`.
    fn act_batch(
        &self,
        obs: ArrayView2<'_, f64>,
        mode: Mode,
        rng: &mut Rng,
    ) -> Result<Array2<f64>> {
        let (_, out) = self.actor.infer_obs(obs, self.od)?;
        let n = obs.nrows();
        let mut a = vec![0.0; n * self.head.dim];
        match mode {
            Mode::Deterministic => self.head.mode(&out, n, &mut a)?,
            Mode::Explore => self.head.sample_actions(&out, n, rng, &mut a)?,
        }
        Ok(self.scale.to_env_rows(&a))
    }
}

impl Critic for Sac {
    /// `min(Q1, Q2)(s, a)` of the online critics (the value SAC's targets and actor use).
    fn q_batch(
        &self,
        obs: ArrayView2<'_, f64>,
        actions: ArrayView2<'_, f64>,
    ) -> Result<Array1<f64>> {
        let x = obs_rows(obs, self.od)?;
        check_action_rows(actions, obs.nrows(), self.head.dim)?;
        let a = self.scale.normalize_view(actions);
        let q = self.min_q(&x, &a, obs.nrows())?;
        Ok(q.iter().map(|v| f64::from(*v)).collect())
    }

    /// The soft value `V(s) = E_{a~π}[min(Q1, Q2)(s, a) - α log π(a|s)]` with the current α,
    /// estimated from one action per row: Explore samples it from `rng` (an unbiased, noisy
    /// estimate); Deterministic takes the mean action `tanh(μ)` and its log-density (no draw; a
    /// biased but smooth estimate for a planner's terminal value).
    fn v_batch(&self, obs: ArrayView2<'_, f64>, mode: Mode, rng: &mut Rng) -> Result<Array1<f64>> {
        let n = obs.nrows();
        let (x, pi) = self.policy(obs, mode, rng)?;
        let q = self.min_q(&x, &pi.action, n)?;
        let alpha = self.log_alpha[0].exp();
        Ok((0..n)
            .map(|i| f64::from(q[i] - alpha * pi.log_prob[i]))
            .collect())
    }
}

impl Agent for Sac {
    fn name(&self) -> &'static str {
        "sac"
    }

    /// The one-row case of [`BatchPolicy::act_batch`], drawing from the agent's own generator.
    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        act_one_row(self, |s| &mut s.rng, obs, mode)
    }
}

impl OffPolicyAgent for Sac {
    fn update(&mut self, batch: &Batch) -> Result<Metrics> {
        let (od, ad) = (self.od, self.scale.dim());
        batch.check(od, ad)?;
        let n = batch.len();
        let head = self.head;
        let s = &mut self.s;
        let obs = batch.obs.as_slice().expect("standard layout");
        let next_obs = batch.next_obs.as_slice().expect("standard layout");
        fit(&mut s.a_norm, n * ad);
        fit(&mut s.x, n * (od + ad));
        fit(&mut s.y, n);
        fit(&mut s.d_q, n);
        fit(&mut s.d_q2, n);
        fit(&mut s.d_x, n * (od + ad));
        fit(&mut s.d_x2, n * (od + ad));
        fit(&mut s.d_out, n * 2 * ad);
        fit(&mut s.actor_out, n * 2 * ad);
        fit(&mut s.next_out, n * 2 * ad);
        fit(&mut s.q_pi1, n);
        fit(&mut s.q_pi2, n);
        self.scale.normalize_rows(
            batch.actions.as_slice().expect("standard layout"),
            &mut s.a_norm,
        );

        // 1. The policy at s (kept on the actor's tape for the actor step) and at s' (second
        //    workspace), side by side. Noise is drawn first, in a fixed order (s, then s'), so the
        //    numbers do not depend on threads.
        s.pi.eps.resize(n * ad, 0.0);
        s.pi_next.eps.resize(n * ad, 0.0);
        tandem_nn::fill_standard_normal(&mut self.rng, &mut s.pi.eps);
        tandem_nn::fill_standard_normal(&mut self.rng, &mut s.pi_next.eps);
        {
            let (actor, ws, next_ws) = (&self.actor.mlp, &mut self.actor.ws, &mut self.next_ws);
            let (out_s, out_n) = (&mut s.actor_out, &mut s.next_out);
            let (r1, r2) = tandem_nn::join(
                || -> Result<()> {
                    out_s.copy_from_slice(actor.forward_train(obs, n, ws, None)?);
                    Ok(())
                },
                || -> Result<()> {
                    out_n.copy_from_slice(actor.forward(next_obs, n, next_ws)?);
                    Ok(())
                },
            );
            r1?;
            r2?;
        }
        head.resample(&s.actor_out, n, &mut s.pi)?;
        head.resample(&s.next_out, n, &mut s.pi_next)?;

        // 2. Entropy coefficient: loss = -log α · mean(log π + H_target); α used below is the
        //    value before this step (stable-baselines3).
        let alpha = self.log_alpha[0].exp();
        let mean_logp = s.pi.log_prob.iter().map(|v| f64::from(*v)).sum::<f64>() / n as f64;
        if self.config.auto_entropy {
            let g = [-(mean_logp as f32 + self.target_entropy)];
            self.alpha_opt.step(&mut self.log_alpha, &g)?;
        }

        // 3. Critic targets with the policy at s', both target critics side by side.
        concat_rows(next_obs, od, &s.pi_next.action, ad, &mut s.x);
        {
            let (t1, t2) = (&mut self.q1_t, &mut self.q2_t);
            let (x, o1, o2) = (&s.x, &mut s.d_q, &mut s.d_q2);
            let (r1, r2) = tandem_nn::join(
                || -> Result<()> {
                    o1.copy_from_slice(t1.mlp.forward(x, n, &mut t1.ws)?);
                    Ok(())
                },
                || -> Result<()> {
                    o2.copy_from_slice(t2.mlp.forward(x, n, &mut t2.ws)?);
                    Ok(())
                },
            );
            r1?;
            r2?;
        }
        let gamma = self.config.gamma as f32;
        for i in 0..n {
            let v = s.d_q[i].min(s.d_q2[i]) - alpha * s.pi_next.log_prob[i];
            s.y[i] = batch.rewards[i] + gamma * (1.0 - batch.terminated[i]) * v;
        }

        // 4. Critics: loss = ½ Σ_k mean (Q_k - y)², one critic per thread.
        concat_rows(obs, od, &s.a_norm, ad, &mut s.x);
        let critic_step = |q: &mut Net, x: &[f32], y: &[f32], d_q: &mut [f32]| -> Result<f64> {
            let qv = q.mlp.forward_train(x, n, &mut q.ws, None)?;
            let mut loss = 0.0f64;
            for i in 0..n {
                let e = qv[i] - y[i];
                loss += 0.5 * f64::from(e * e) / n as f64;
                d_q[i] = e / n as f32;
            }
            q.mlp.backward(&mut q.ws, d_q, Some(&mut q.grads), None)?;
            q.step()?;
            Ok(loss)
        };
        let (l1, l2) = {
            let (q1, q2) = (&mut self.q1, &mut self.q2);
            let (x, y, d1, d2) = (&s.x, &s.y, &mut s.d_q, &mut s.d_q2);
            tandem_nn::join(|| critic_step(q1, x, y, d1), || critic_step(q2, x, y, d2))
        };
        let critic_loss = l1? + l2?;
        if !critic_loss.is_finite() {
            return Err(AgentError::NonFinite {
                what: "sac critic loss",
                value: critic_loss,
            });
        }

        // 5. Actor through the updated critics: dQmin/da from the smaller critic of each row.
        //    Each thread also moves its target critic towards the updated critic (stable-baselines3
        //    does this after the actor step; the critics do not change in between, so the numbers
        //    are the same).
        concat_rows(obs, od, &s.pi.action, ad, &mut s.x);
        {
            let (q1, q2) = (&mut self.q1, &mut self.q2);
            let (t1, t2) = (&mut self.q1_t, &mut self.q2_t);
            let tau = self.config.tau;
            let (x, o1, o2) = (&s.x, &mut s.q_pi1, &mut s.q_pi2);
            let (r1, r2) = tandem_nn::join(
                || -> Result<()> {
                    t1.polyak(q1, tau)?;
                    o1.copy_from_slice(q1.mlp.forward_train(x, n, &mut q1.ws, None)?);
                    Ok(())
                },
                || -> Result<()> {
                    t2.polyak(q2, tau)?;
                    o2.copy_from_slice(q2.mlp.forward_train(x, n, &mut q2.ws, None)?);
                    Ok(())
                },
            );
            r1?;
            r2?;
        }
        let mut min_q = 0.0f64;
        for i in 0..n {
            let first = s.q_pi1[i] <= s.q_pi2[i];
            min_q += f64::from(s.q_pi1[i].min(s.q_pi2[i]));
            s.d_q[i] = if first { 1.0 } else { 0.0 };
            s.d_q2[i] = if first { 0.0 } else { 1.0 };
        }
        let actor_loss = (f64::from(alpha) * mean_logp) - min_q / n as f64;
        {
            let (q1, q2) = (&mut self.q1, &mut self.q2);
            let (d1, d2, dx1, dx2) = (&s.d_q, &s.d_q2, &mut s.d_x, &mut s.d_x2);
            let (r1, r2) = tandem_nn::join(
                || q1.mlp.backward(&mut q1.ws, d1, None, Some(dx1)),
                || q2.mlp.backward(&mut q2.ws, d2, None, Some(dx2)),
            );
            r1?;
            r2?;
        }
        // dQmin/da (the smaller critic's input gradient; the other's d_q is zero) into `d_a`.
        fit(&mut s.dq_da, n * ad);
        for i in 0..n {
            for j in 0..ad {
                let k = i * (od + ad) + od + j;
                s.dq_da[i * ad + j] = s.d_x[k] + s.d_x2[k];
            }
        }
        Sac::actor_output_grad(
            &head,
            &s.pi,
            &s.dq_da,
            alpha,
            (&mut s.d_a, &mut s.d_logp),
            &mut s.d_out,
        )?;
        self.actor.mlp.backward(
            &mut self.actor.ws,
            &s.d_out,
            Some(&mut self.actor.grads),
            None,
        )?;
        self.actor.step()?;

        let mut m = Metrics::default();
        m.push("critic_loss", critic_loss);
        m.push("actor_loss", actor_loss);
        m.push("alpha", f64::from(alpha));
        m.push("entropy", -mean_logp);
        Ok(m)
    }
}
