//! Hot paths of `tandem-nn`: the network work of one RL update, at the sizes we compare against
//! PyTorch (critic update, dynamics-model step, batched prediction, and one full SAC update with
//! stable-baselines3's defaults).
//!
//! Also (`conv`): each convolution of p2's pixel model (batch 32, forward and backward) through
//! `tandem_nn::conv` and through candle's own ops.
//!
//! Also (`elementwise`): [`tandem_nn::fastmath`]'s vectorized functions beside the standard
//! library's per-element libm calls over the same 65 536 inputs, and the Gaussian head's forward
//! pass and loss at one ensemble member's minibatch (256 rows × 18 outputs).
//!
//! Run: `cargo bench --bench nn` (medians are what the notes quote).

#![allow(clippy::needless_range_loop)]

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use rand::Rng as _;
use tandem_core::seeding::{rng_from_seed, Rng};
use tandem_nn::{
    fastmath, fill_standard_normal, AdaGrad, AdaGradConfig, Adam, AdamConfig, GaussianHead,
    GaussianOutput, Mlp, MlpConfig, MlpWorkspace, Optimizer, TanhGaussian, TanhGaussianSample,
};

fn random(n: usize, rng: &mut Rng) -> Vec<f32> {
    (0..n).map(|_| rng.random::<f32>() * 2.0 - 1.0).collect()
}

/// One critic regression step: forward, MSE gradient, backward, Adam.
struct CriticStep {
    net: Mlp,
    opt: Adam,
    ws: MlpWorkspace,
    grads: Vec<f32>,
    d_out: Vec<f32>,
    x: Vec<f32>,
    y: Vec<f32>,
    batch: usize,
}

impl CriticStep {
    fn step(&mut self) {
        let pred = self
            .net
            .forward_train(&self.x, self.batch, &mut self.ws, None)
            .unwrap();
        tandem_nn::mse(pred, &self.y, Some(&mut self.d_out)).unwrap();
        self.net
            .backward(&mut self.ws, &self.d_out, Some(&mut self.grads), None)
            .unwrap();
        self.opt.step(self.net.params_mut(), &self.grads).unwrap();
    }
}

fn critic_update(c: &mut Criterion) {
    let mut rng = rng_from_seed(0);
    let batch = 256;
    let net = Mlp::new(MlpConfig::new(&[23, 256, 256, 1]), &mut rng).unwrap();
    let mut s = CriticStep {
        opt: Adam::new(AdamConfig::with_lr(1e-3), net.num_params()).unwrap(),
        ws: net.workspace(),
        grads: net.zero_grads(),
        d_out: vec![0.0; batch],
        x: random(batch * 23, &mut rng),
        y: random(batch, &mut rng),
        batch,
        net,
    };
    c.bench_function("critic update 23-256-256-1 b256 adam", |b| {
        b.iter(|| s.step())
    });
}

fn dynamics_step(c: &mut Criterion) {
    let mut rng = rng_from_seed(1);
    let batch = 256;
    let mut net = Mlp::new(
        MlpConfig::new(&[23, 400, 400, 400, 17]).dropout(0.3),
        &mut rng,
    )
    .unwrap();
    let mut opt = AdaGrad::new(AdaGradConfig::default(), net.num_params()).unwrap();
    let mut ws = net.workspace();
    let mut grads = net.zero_grads();
    let mut d_out = vec![0.0; batch * 17];
    let x = random(batch * 23, &mut rng);
    let y = random(batch * 17, &mut rng);
    let mut drop_rng = rng_from_seed(2);
    c.bench_function("dynamics step 23-400x3-17 dropout0.3 b256 adagrad", |b| {
        b.iter(|| {
            let pred = net
                .forward_train(&x, batch, &mut ws, Some(&mut drop_rng))
                .unwrap();
            tandem_nn::mse(pred, &y, Some(&mut d_out)).unwrap();
            net.backward(&mut ws, &d_out, Some(&mut grads), None)
                .unwrap();
            opt.step(net.params_mut(), &grads).unwrap();
        })
    });
    let x500 = random(500 * 23, &mut rng);
    c.bench_function("dynamics forward 23-400x3-17 b500", |b| {
        b.iter(|| black_box(net.forward(&x500, 500, &mut ws).unwrap()[0]))
    });
}

fn actor_forward(c: &mut Criterion) {
    let mut rng = rng_from_seed(3);
    let net = Mlp::new(MlpConfig::new(&[17, 256, 256, 12]), &mut rng).unwrap();
    let mut ws = net.workspace();
    let x = random(17, &mut rng);
    c.bench_function("actor forward 17-256-256-12 b1", |b| {
        b.iter(|| black_box(net.forward(&x, 1, &mut ws).unwrap()[0]))
    });
    let sac_actor = Mlp::new(MlpConfig::new(&[3, 256, 256, 2]), &mut rng).unwrap();
    let xs = random(3, &mut rng);
    c.bench_function("actor forward 3-256-256-2 b1", |b| {
        b.iter(|| black_box(sac_actor.forward(&xs, 1, &mut ws).unwrap()[0]))
    });
}

/// One SAC update with stable-baselines3's defaults (Haarnoja et al. 2018 with automatic entropy
/// tuning): twin critics and their targets (obs 3 + act 1 → 256 → 256 → 1), a tanh-Gaussian actor
/// (3 → 256 → 256 → 2·1), batch 256, Adam 3e-4 everywhere, τ = 0.005, γ = 0.99.
struct Sac {
    obs_dim: usize,
    act_dim: usize,
    batch: usize,
    actor: Mlp,
    critics: [Mlp; 2],
    targets: [Mlp; 2],
    actor_opt: Adam,
    critic_opts: [Adam; 2],
    log_alpha: f32,
    alpha_opt: Adam,
    target_entropy: f32,
    head: TanhGaussian,
    rng: Rng,
    // scratch
    ws_actor: MlpWorkspace,
    ws_critic: [MlpWorkspace; 2],
    ws_target: MlpWorkspace,
    pi: TanhGaussianSample,
    pi_next: TanhGaussianSample,
    sa: Vec<f32>,
    q_target: Vec<f32>,
    q_min: Vec<f32>,
    d_q: Vec<f32>,
    d_sa: [Vec<f32>; 2],
    d_act: Vec<f32>,
    d_logp: Vec<f32>,
    d_head: Vec<f32>,
    grads_actor: Vec<f32>,
    grads_critic: Vec<f32>,
    // batch
    obs: Vec<f32>,
    act: Vec<f32>,
    rew: Vec<f32>,
    next_obs: Vec<f32>,
    done: Vec<f32>,
}

fn concat_rows(a: &[f32], da: usize, b: &[f32], db: usize, out: &mut [f32]) {
    for ((o, ra), rb) in out
        .chunks_exact_mut(da + db)
        .zip(a.chunks_exact(da))
        .zip(b.chunks_exact(db))
    {
        o[..da].copy_from_slice(ra);
        o[da..].copy_from_slice(rb);
    }
}

impl Sac {
    fn new(seed: u64) -> Self {
        let (obs_dim, act_dim, batch) = (3, 1, 256);
        let mut rng = rng_from_seed(seed);
        let actor = Mlp::new(MlpConfig::new(&[obs_dim, 256, 256, 2 * act_dim]), &mut rng).unwrap();
        let qcfg = MlpConfig::new(&[obs_dim + act_dim, 256, 256, 1]);
        let critics = [
            Mlp::new(qcfg.clone(), &mut rng).unwrap(),
            Mlp::new(qcfg, &mut rng).unwrap(),
        ];
        let targets = critics.clone();
        let adam = |n| Adam::new(AdamConfig::with_lr(3e-4), n).unwrap();
        let np_q = critics[0].num_params();
        Self {
            obs_dim,
            act_dim,
            batch,
            actor_opt: adam(actor.num_params()),
            critic_opts: [adam(np_q), adam(np_q)],
            grads_actor: actor.zero_grads(),
            grads_critic: vec![0.0; np_q],
            actor,
            critics,
            targets,
            log_alpha: 0.0,
            alpha_opt: adam(1),
            target_entropy: -(act_dim as f32),
            head: TanhGaussian::new(act_dim),
            ws_actor: MlpWorkspace::default(),
            ws_critic: Default::default(),
            ws_target: MlpWorkspace::default(),
            pi: TanhGaussianSample::default(),
            pi_next: TanhGaussianSample::default(),
            sa: vec![0.0; batch * (obs_dim + act_dim)],
            q_target: vec![0.0; batch],
            q_min: vec![0.0; batch],
            d_q: vec![0.0; batch],
            d_sa: [
                vec![0.0; batch * (obs_dim + act_dim)],
                vec![0.0; batch * (obs_dim + act_dim)],
            ],
            d_act: vec![0.0; batch * act_dim],
            d_logp: vec![0.0; batch],
            d_head: vec![0.0; batch * 2 * act_dim],
            obs: random(batch * obs_dim, &mut rng),
            act: random(batch * act_dim, &mut rng),
            rew: random(batch, &mut rng),
            next_obs: random(batch * obs_dim, &mut rng),
            done: (0..batch)
                .map(|i| if i % 50 == 0 { 1.0 } else { 0.0 })
                .collect(),
            rng,
        }
    }

    fn update(&mut self) {
        let (b, od, ad) = (self.batch, self.obs_dim, self.act_dim);
        let bf = b as f32;
        // Policy sample at s, and the entropy temperature step.
        let out = self
            .actor
            .forward_train(&self.obs, b, &mut self.ws_actor, None)
            .unwrap();
        self.head
            .sample(out, b, &mut self.rng, &mut self.pi)
            .unwrap();
        let alpha = self.log_alpha.exp();
        let g_log_alpha = -self
            .pi
            .log_prob
            .iter()
            .map(|lp| lp + self.target_entropy)
            .sum::<f32>()
            / bf;
        let mut la = [self.log_alpha];
        self.alpha_opt.step(&mut la, &[g_log_alpha]).unwrap();
        self.log_alpha = la[0];

        // Targets: y = r + γ(1-d)(min Q'(s', a') - α log π(a'|s')).
        let out = self
            .actor
            .forward(&self.next_obs, b, &mut self.ws_target)
            .unwrap();
        self.head
            .sample(out, b, &mut self.rng, &mut self.pi_next)
            .unwrap();
        concat_rows(&self.next_obs, od, &self.pi_next.action, ad, &mut self.sa);
        self.q_target.fill(f32::INFINITY);
        for t in &self.targets {
            let q = t.forward(&self.sa, b, &mut self.ws_target).unwrap();
            for (m, v) in self.q_target.iter_mut().zip(q) {
                *m = m.min(*v);
            }
        }
        for i in 0..b {
            let soft = self.q_target[i] - alpha * self.pi_next.log_prob[i];
            self.q_target[i] = self.rew[i] + 0.99 * (1.0 - self.done[i]) * soft;
        }

        // Critic step: loss = ½ Σ_k mse(Q_k(s, a), y).
        concat_rows(&self.obs, od, &self.act, ad, &mut self.sa);
        for k in 0..2 {
            let q = self.critics[k]
                .forward_train(&self.sa, b, &mut self.ws_critic[k], None)
                .unwrap();
            for ((d, qv), y) in self.d_q.iter_mut().zip(q).zip(&self.q_target) {
                *d = (qv - y) / bf; // ½ · 2(q - y)/B
            }
            self.critics[k]
                .backward(
                    &mut self.ws_critic[k],
                    &self.d_q,
                    Some(&mut self.grads_critic),
                    None,
                )
                .unwrap();
            self.critic_opts[k]
                .step(self.critics[k].params_mut(), &self.grads_critic)
                .unwrap();
        }

        // Actor step: loss = mean(α log π(a|s) - min_k Q_k(s, a)), a = tanh-Gaussian sample.
        concat_rows(&self.obs, od, &self.pi.action, ad, &mut self.sa);
        self.q_min.fill(f32::INFINITY);
        let mut which = [0u8; 256];
        for k in 0..2 {
            let q = self.critics[k]
                .forward_train(&self.sa, b, &mut self.ws_critic[k], None)
                .unwrap();
            for i in 0..b {
                if q[i] < self.q_min[i] {
                    self.q_min[i] = q[i];
                    which[i] = k as u8;
                }
            }
        }
        for k in 0..2 {
            for i in 0..b {
                self.d_q[i] = if which[i] as usize == k {
                    -1.0 / bf
                } else {
                    0.0
                };
            }
            self.critics[k]
                .backward(
                    &mut self.ws_critic[k],
                    &self.d_q,
                    None,
                    Some(&mut self.d_sa[k]),
                )
                .unwrap();
        }
        for i in 0..b {
            for j in 0..ad {
                let c = i * (od + ad) + od + j;
                self.d_act[i * ad + j] = self.d_sa[0][c] + self.d_sa[1][c];
            }
        }
        self.d_logp.fill(alpha / bf);
        self.head
            .backward(
                &self.pi,
                Some(&self.d_act),
                Some(&self.d_logp),
                &mut self.d_head,
            )
            .unwrap();
        self.actor
            .backward(
                &mut self.ws_actor,
                &self.d_head,
                Some(&mut self.grads_actor),
                None,
            )
            .unwrap();
        self.actor_opt
            .step(self.actor.params_mut(), &self.grads_actor)
            .unwrap();

        for k in 0..2 {
            tandem_nn::polyak_update(
                self.targets[k].params_mut(),
                self.critics[k].params(),
                0.005,
            )
            .unwrap();
        }
    }
}

/// The same SAC update with the two critics' work on two threads (`tandem_nn::join`): target
/// critics, critic steps and the actor-loss passes through each critic run side by side; the
/// policy samples at `s` and `s'` too. Noise is drawn up front in a fixed order, so the numbers do
/// not depend on thread timing.
struct SacPar {
    inner: Sac,
    ws_actor_next: MlpWorkspace,
    ws_target2: MlpWorkspace,
    eps: Vec<f32>,
    eps_next: Vec<f32>,
    sa_next: Vec<f32>,
    sa_pi: Vec<f32>,
    q_next: [Vec<f32>; 2],
    q_pi: [Vec<f32>; 2],
    d_q2: [Vec<f32>; 2],
    grads_critic2: Vec<f32>,
}

type CriticRefs<'a> = (
    &'a mut Mlp,
    &'a mut Adam,
    &'a mut MlpWorkspace,
    &'a mut Vec<f32>,
    &'a mut Vec<f32>,
    &'a mut Vec<f32>,
);

impl SacPar {
    fn new(seed: u64) -> Self {
        let inner = Sac::new(seed);
        let (b, w) = (inner.batch, inner.obs_dim + inner.act_dim);
        Self {
            ws_actor_next: MlpWorkspace::default(),
            ws_target2: MlpWorkspace::default(),
            eps: vec![0.0; b * inner.act_dim],
            eps_next: vec![0.0; b * inner.act_dim],
            sa_next: vec![0.0; b * w],
            sa_pi: vec![0.0; b * w],
            q_next: [vec![0.0; b], vec![0.0; b]],
            q_pi: [vec![0.0; b], vec![0.0; b]],
            d_q2: [vec![0.0; b], vec![0.0; b]],
            grads_critic2: vec![0.0; inner.grads_critic.len()],
            inner,
        }
    }

    fn update(&mut self) {
        let Self {
            inner: s,
            ws_actor_next,
            ws_target2,
            eps,
            eps_next,
            sa_next,
            sa_pi,
            q_next,
            q_pi,
            d_q2,
            grads_critic2,
        } = self;
        let (b, od, ad) = (s.batch, s.obs_dim, s.act_dim);
        let bf = b as f32;
        fill_standard_normal(&mut s.rng, eps);
        fill_standard_normal(&mut s.rng, eps_next);
        // Policy at s (training pass) and at s' (inference) side by side.
        {
            let (actor, head) = (&s.actor, s.head);
            let (ws_a, pi, pi_next) = (&mut s.ws_actor, &mut s.pi, &mut s.pi_next);
            let (obs, next_obs, eps, eps_next) = (&s.obs, &s.next_obs, &*eps, &*eps_next);
            tandem_nn::join(
                || {
                    let out = actor.forward_train(obs, b, ws_a, None).unwrap();
                    head.sample_with_noise(out, b, eps, pi).unwrap();
                },
                || {
                    let out = actor.forward(next_obs, b, ws_actor_next).unwrap();
                    head.sample_with_noise(out, b, eps_next, pi_next).unwrap();
                },
            );
        }
        let alpha = s.log_alpha.exp();
        let g_log_alpha = -s
            .pi
            .log_prob
            .iter()
            .map(|lp| lp + s.target_entropy)
            .sum::<f32>()
            / bf;
        let mut la = [s.log_alpha];
        s.alpha_opt.step(&mut la, &[g_log_alpha]).unwrap();
        s.log_alpha = la[0];

        concat_rows(&s.next_obs, od, &s.pi_next.action, ad, sa_next);
        {
            let [t0, t1] = &s.targets;
            let [q0, q1] = q_next;
            let (w0, w1) = (&mut s.ws_target, ws_target2);
            let sa_next = &*sa_next;
            tandem_nn::join(
                || q0.copy_from_slice(t0.forward(sa_next, b, w0).unwrap()),
                || q1.copy_from_slice(t1.forward(sa_next, b, w1).unwrap()),
            );
        }
        for i in 0..b {
            let soft = q_next[0][i].min(q_next[1][i]) - alpha * s.pi_next.log_prob[i];
            s.q_target[i] = s.rew[i] + 0.99 * (1.0 - s.done[i]) * soft;
        }

        // Critic steps, then each critic's forward at (s, a_pi), on two threads.
        concat_rows(&s.obs, od, &s.act, ad, &mut s.sa);
        concat_rows(&s.obs, od, &s.pi.action, ad, sa_pi);
        {
            let [c0, c1] = &mut s.critics;
            let [o0, o1] = &mut s.critic_opts;
            let [w0, w1] = &mut s.ws_critic;
            let [p0, p1] = q_pi;
            let [d0, d1] = d_q2;
            let (g0, g1) = (&mut s.grads_critic, grads_critic2);
            let (sa, sa_pi, y) = (&s.sa, &*sa_pi, &s.q_target);
            let critic_job = |(c, o, w, g, d, qp): CriticRefs| {
                let q = c.forward_train(sa, b, w, None).unwrap();
                for ((dv, qv), yv) in d.iter_mut().zip(q).zip(y) {
                    *dv = (qv - yv) / bf;
                }
                c.backward(w, d, Some(g), None).unwrap();
                o.step(c.params_mut(), g).unwrap();
                qp.copy_from_slice(c.forward_train(sa_pi, b, w, None).unwrap());
            };
            tandem_nn::join(
                || critic_job((c0, o0, w0, g0, d0, p0)),
                || critic_job((c1, o1, w1, g1, d1, p1)),
            );
        }
        for i in 0..b {
            let first = q_pi[0][i] <= q_pi[1][i];
            d_q2[0][i] = if first { -1.0 / bf } else { 0.0 };
            d_q2[1][i] = if first { 0.0 } else { -1.0 / bf };
        }
        {
            let [c0, c1] = &s.critics;
            let [w0, w1] = &mut s.ws_critic;
            let [x0, x1] = &mut s.d_sa;
            let [d0, d1] = &*d_q2;
            tandem_nn::join(
                || c0.backward(w0, d0, None, Some(x0)).unwrap(),
                || c1.backward(w1, d1, None, Some(x1)).unwrap(),
            );
        }
        for i in 0..b {
            for j in 0..ad {
                let c = i * (od + ad) + od + j;
                s.d_act[i * ad + j] = s.d_sa[0][c] + s.d_sa[1][c];
            }
        }
        s.d_logp.fill(alpha / bf);
        s.head
            .backward(&s.pi, Some(&s.d_act), Some(&s.d_logp), &mut s.d_head)
            .unwrap();
        s.actor
            .backward(&mut s.ws_actor, &s.d_head, Some(&mut s.grads_actor), None)
            .unwrap();
        s.actor_opt
            .step(s.actor.params_mut(), &s.grads_actor)
            .unwrap();
        for k in 0..2 {
            tandem_nn::polyak_update(s.targets[k].params_mut(), s.critics[k].params(), 0.005)
                .unwrap();
        }
    }
}

fn sac_update(c: &mut Criterion) {
    let mut sac = Sac::new(7);
    c.bench_function("sac update pendulum-shaped b256 2x256", |b| {
        b.iter(|| sac.update())
    });
    let mut par = SacPar::new(7);
    c.bench_function(
        "sac update pendulum-shaped b256 2x256, critics on 2 threads",
        |b| b.iter(|| par.update()),
    );
}

/// One forward and backward pass (`Σ y` as the loss, gradients for input and kernel) of each
/// convolution of p2's pixel model at batch 32, through `tandem_nn::conv` and through candle.
fn conv(c: &mut Criterion) {
    use candle_core::{Device, Tensor, Var};
    type Conv = fn(&Tensor, &Tensor, usize) -> candle_core::Result<Tensor>;
    let ours: Conv = |x, k, s| tandem_nn::conv::conv2d(x, k, s, 1);
    let candle: Conv = |x, k, s| x.conv2d(k, 1, s, 1, 1);
    let ours_t: Conv = |x, k, s| tandem_nn::conv::conv_transpose2d(x, k, s, 1, 0);
    let candle_t: Conv = |x, k, s| x.conv_transpose2d(k, 1, 0, s, 1);
    let mut rng = rng_from_seed(11);
    let mut var = |dims: [usize; 4]| {
        let t = Tensor::from_vec(random(dims.iter().product(), &mut rng), &dims, &Device::Cpu);
        Var::from_tensor(&t.unwrap()).unwrap()
    };
    let mut group = c.benchmark_group("conv");
    // (layer, input, kernel, stride, transposed)
    let layers = [
        ("enc0", [32, 12, 16, 16], [32, 12, 4, 4], 2, false),
        ("enc1", [32, 32, 8, 8], [64, 32, 4, 4], 2, false),
        ("enc2", [32, 64, 4, 4], [64, 64, 3, 3], 1, false),
        ("dec0 (transposed)", [32, 64, 4, 4], [64, 64, 3, 3], 1, true),
        ("dec1 (transposed)", [32, 64, 4, 4], [64, 32, 4, 4], 2, true),
        ("dec2 (transposed)", [32, 32, 8, 8], [32, 3, 4, 4], 2, true),
    ];
    for (layer, xd, kd, stride, transposed) in layers {
        let (x, k) = (var(xd), var(kd));
        let impls = if transposed {
            [("ours", ours_t), ("candle", candle_t)]
        } else {
            [("ours", ours), ("candle", candle)]
        };
        for (name, f) in impls {
            group.bench_function(format!("{layer} {xd:?} * {kd:?} fwd+bwd, {name}"), |b| {
                b.iter(|| {
                    let y = f(x.as_tensor(), k.as_tensor(), stride).unwrap();
                    black_box(y.sum_all().unwrap().backward().unwrap())
                })
            });
        }
    }
    group.finish();
}

/// Each function over 65 536 inputs in [-8, 8]: the vectorized form against libm's, one call per
/// element, in the same run.
fn elementwise(c: &mut Criterion) {
    let mut rng = rng_from_seed(11);
    let x: Vec<f32> = random(1 << 16, &mut rng).iter().map(|v| 8.0 * v).collect();
    let mut out = vec![0.0f32; x.len()];
    let mut group = c.benchmark_group("elementwise");
    type Pair = (&'static str, fastmath::Function, fn(f32) -> f32);
    let pairs: [Pair; 5] = [
        ("exp", fastmath::Function::Exp, f32::exp),
        ("softplus", fastmath::Function::Softplus, |v| {
            v.max(0.0) + (-v.abs()).exp().ln_1p()
        }),
        ("sigmoid", fastmath::Function::Sigmoid, |v| {
            1.0 / (1.0 + (-v).exp())
        }),
        ("silu", fastmath::Function::Silu, |v| v / (1.0 + (-v).exp())),
        ("tanh", fastmath::Function::Tanh, f32::tanh),
    ];
    // Both sides copy the inputs first, then work in place.
    for (name, fast, libm) in pairs {
        group.bench_function(format!("{name} 64k fastmath"), |b| {
            b.iter(|| {
                out.copy_from_slice(black_box(&x));
                fastmath::apply(fast, &mut out);
            })
        });
        group.bench_function(format!("{name} 64k libm"), |b| {
            b.iter(|| {
                out.copy_from_slice(black_box(&x));
                for v in out.iter_mut() {
                    *v = libm(*v);
                }
            })
        });
    }
    let (rows, dim) = (256, 18);
    let head = GaussianHead::new(dim);
    let net_out: Vec<f32> = random(rows * 2 * dim, &mut rng)
        .iter()
        .map(|v| 3.0 * v)
        .collect();
    let target = random(rows * dim, &mut rng);
    let mut g = GaussianOutput::default();
    let (mut d_mean, mut d_lv) = (vec![0.0; rows * dim], vec![0.0; rows * dim]);
    group.bench_function("gaussian head forward + nll 256x18", |b| {
        b.iter(|| {
            head.forward(black_box(&net_out), rows, &mut g).unwrap();
            tandem_nn::gaussian_nll(
                &g.mean,
                &g.log_var,
                &target,
                Some(&mut d_mean),
                Some(&mut d_lv),
            )
            .unwrap()
        })
    });
    group.finish();
}

criterion_group!(
    benches,
    critic_update,
    dynamics_step,
    actor_forward,
    sac_update,
    conv,
    elementwise
);
criterion_main!(benches);
