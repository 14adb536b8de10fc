//! SAC (Haarnoja et al. 2018) with twin critics, target critics, automatic entropy tuning and a
//! tanh-squashed Gaussian actor, following stable-baselines3's `SAC.train` step by step.
//!
//! The actor outputs `[mean, log_std]` (log-std clamped to `[log_std_min, log_std_max]`, zero
//! gradient outside, as `torch.clamp`); an action is `a = tanh(u)`, `u = mean + std ε`,
//! `ε ~ N(0, I)` from the agent's own seeded generator, with
//! `log π(a|s) = Σ_j [-ε_j²/2 - log_std_j - log(2π)/2 - log(1 - a_j² + 1e-6)]`.
//!
//! The actor gradient is derived by hand (reparametrization): with
//! `L = mean_i(α log π_i - min(Q1, Q2)(s_i, a_i))`,
//! `dL/du = (α · 2a(1-a²)/(1-a²+1e-6) - dQmin/da · (1-a²)) / n`,
//! `dL/dmean = dL/du`, `dL/dlog_std = -α/n + dL/du · std · ε`, where `dQmin/da` is the input
//! gradient of whichever critic is smaller for that row. Tested against finite differences.

use rand_distr::{Distribution, StandardNormal};
use tandem_core::{Action, Rng, SeedStream, Space};
use tandem_nn::{Adam, AdamConfig, Checkpoint, Checkpointable, MlpConfig, MlpWorkspace, Optimizer};

use crate::agent::{check_obs, Agent, Batch, Metrics, Mode, OffPolicyAgent};
use crate::common::{
    check_header, concat_rows, fit, obs_dim, save_header, ActionScale, Net, Target,
};
use crate::config::SacConfig;
use crate::error::{AgentError, Result};

const LOG_2PI_HALF: f32 = 0.918_938_5; // ln(2π)/2
const SQUASH_EPS: f32 = 1e-6;

/// A SAC agent.
#[derive(Debug, Clone)]
pub struct Sac {
    config: SacConfig,
    od: usize,
    scale: ActionScale,
    actor: Net,
    q1: Net,
    q2: Net,
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
    eps: Vec<f32>,
    act: Vec<f32>,
    logp: Vec<f32>,
    next_act: Vec<f32>,
    next_logp: Vec<f32>,
    actor_out: Vec<f32>,
    eps_next: Vec<f32>,
    q_pi1: Vec<f32>,
    q_pi2: Vec<f32>,
}

/// Draws `ε ~ N(0, I)` into `eps` from `rng`.
fn draw_noise(rng: &mut Rng, eps: &mut [f32]) {
    for e in eps.iter_mut() {
        *e = StandardNormal.sample(rng);
    }
}

/// `a = tanh(mean + std ε)` for each row of `out` (`n x 2ad`: mean then log-std) with the given
/// noise, and its log-probability; clamps log-std in place. Writes `act` (`n x ad`), `logp` (`n`).
fn squash(
    out: &mut [f32],
    ad: usize,
    (lo, hi): (f32, f32),
    eps: &[f32],
    act: &mut [f32],
    logp: &mut [f32],
) {
    for (i, row) in out.chunks_exact_mut(2 * ad).enumerate() {
        let mut lp = 0.0f32;
        for j in 0..ad {
            let ls = row[ad + j].clamp(lo, hi);
            row[ad + j] = ls;
            let e = eps[i * ad + j];
            let a = (row[j] + ls.exp() * e).tanh();
            act[i * ad + j] = a;
            lp += -0.5 * e * e - ls - LOG_2PI_HALF - (1.0 - a * a + SQUASH_EPS).ln();
        }
        logp[i] = lp;
    }
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
        Ok(Self {
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

    /// The actor loss's gradient wrt the actor outputs (`n x 2ad`), given the clamped outputs,
    /// the noise, the squashed actions and `dQmin/da` (`n x ad`).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn actor_output_grad(
        out: &[f32],
        raw_log_std_in_range: impl Fn(usize) -> bool,
        eps: &[f32],
        act: &[f32],
        dq_da: &[f32],
        alpha: f32,
        ad: usize,
        d_out: &mut [f32],
    ) {
        let n = eps.len() / ad;
        let inv_n = 1.0 / n as f32;
        for i in 0..n {
            for j in 0..ad {
                let k = i * ad + j;
                let a = act[k];
                let one_m = 1.0 - a * a;
                let g_u =
                    (alpha * 2.0 * a * one_m / (one_m + SQUASH_EPS) - dq_da[k] * one_m) * inv_n;
                let std = out[i * 2 * ad + ad + j].exp();
                d_out[i * 2 * ad + j] = g_u;
                d_out[i * 2 * ad + ad + j] = if raw_log_std_in_range(i * 2 * ad + ad + j) {
                    -alpha * inv_n + g_u * std * eps[k]
                } else {
                    0.0
                };
            }
        }
    }
}

impl Agent for Sac {
    fn name(&self) -> &'static str {
        "sac"
    }

    fn act(&mut self, obs: &[f64], mode: Mode) -> Result<Action> {
        check_obs(obs, self.od)?;
        let ad = self.scale.dim();
        let x: Vec<f32> = obs.iter().map(|v| *v as f32).collect();
        let mut out = self.actor.mlp.forward(&x, 1, &mut self.actor.ws)?.to_vec();
        let a: Vec<f32> = match mode {
            Mode::Deterministic => out[..ad].iter().map(|m| m.tanh()).collect(),
            Mode::Explore => {
                let (mut e, mut a, mut lp) = (vec![0.0; ad], vec![0.0; ad], [0.0f32]);
                let c = &self.config;
                let lims = (c.log_std_min as f32, c.log_std_max as f32);
                draw_noise(&mut self.rng, &mut e);
                squash(&mut out, ad, lims, &e, &mut a, &mut lp);
                a
            }
        };
        Ok(Action::Continuous(self.scale.to_env(&a)))
    }
}

impl OffPolicyAgent for Sac {
    fn update(&mut self, batch: &Batch) -> Result<Metrics> {
        let (od, ad) = (self.od, self.scale.dim());
        batch.check(od, ad)?;
        let n = batch.len();
        let lims = (
            self.config.log_std_min as f32,
            self.config.log_std_max as f32,
        );
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
        fit(&mut s.eps, n * ad);
        fit(&mut s.act, n * ad);
        fit(&mut s.logp, n);
        fit(&mut s.next_act, n * ad);
        fit(&mut s.next_logp, n);
        fit(&mut s.actor_out, n * 2 * ad);
        fit(&mut s.eps_next, n * ad);
        fit(&mut s.q_pi1, n);
        fit(&mut s.q_pi2, n);
        self.scale.normalize_rows(
            batch.actions.as_slice().expect("standard layout"),
            &mut s.a_norm,
        );

        // 1. The policy at s (kept on the actor's tape for the actor step) and at s' (second
        //    workspace), side by side. Noise is drawn first, in a fixed order (s, then s'), so the
        //    numbers do not depend on threads.
        draw_noise(&mut self.rng, &mut s.eps);
        draw_noise(&mut self.rng, &mut s.eps_next);
        {
            let (actor, ws, next_ws) = (&self.actor.mlp, &mut self.actor.ws, &mut self.next_ws);
            let (out_s, out_n) = (&mut s.actor_out, &mut s.d_out);
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
        squash(&mut s.actor_out, ad, lims, &s.eps, &mut s.act, &mut s.logp);
        squash(
            &mut s.d_out,
            ad,
            lims,
            &s.eps_next,
            &mut s.next_act,
            &mut s.next_logp,
        );

        // 2. Entropy coefficient: loss = -log α · mean(log π + H_target); α used below is the
        //    value before this step (stable-baselines3).
        let alpha = self.log_alpha[0].exp();
        let mean_logp = s.logp.iter().map(|v| f64::from(*v)).sum::<f64>() / n as f64;
        if self.config.auto_entropy {
            let g = [-(mean_logp as f32 + self.target_entropy)];
            self.alpha_opt.step(&mut self.log_alpha, &g)?;
        }

        // 3. Critic targets with the policy at s', both target critics side by side.
        concat_rows(next_obs, od, &s.next_act, ad, &mut s.x);
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
            let v = s.d_q[i].min(s.d_q2[i]) - alpha * s.next_logp[i];
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
        concat_rows(obs, od, &s.act, ad, &mut s.x);
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
        // dQmin/da into d_q-sized rows of `next_act` (reused as scratch).
        for i in 0..n {
            for j in 0..ad {
                let k = i * (od + ad) + od + j;
                s.next_act[i * ad + j] = s.d_x[k] + s.d_x2[k];
            }
        }
        let actor_out = &s.actor_out;
        let (lo, hi) = lims;
        // The clamp passes gradient only where the raw log-std lay inside [lo, hi]; the clamped
        // value equals the raw one exactly there.
        let in_range = |k: usize| actor_out[k] > lo && actor_out[k] < hi;
        Sac::actor_output_grad(
            actor_out,
            in_range,
            &s.eps,
            &s.act,
            &s.next_act,
            alpha,
            ad,
            &mut s.d_out,
        );
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
