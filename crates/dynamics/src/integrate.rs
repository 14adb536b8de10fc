//! Fixed-step integrators for `ẋ = f(x, u)` with `u` held constant over the step (zero-order hold).

use nalgebra::DVector;

/// One explicit-Euler step of length `h`.
pub fn euler<F>(f: F, x: &DVector<f64>, u: &DVector<f64>, h: f64) -> DVector<f64>
where
    F: Fn(&DVector<f64>, &DVector<f64>) -> DVector<f64>,
{
    x + f(x, u) * h
}

/// One classical fourth-order Runge–Kutta step of length `h`.
pub fn rk4<F>(f: F, x: &DVector<f64>, u: &DVector<f64>, h: f64) -> DVector<f64>
where
    F: Fn(&DVector<f64>, &DVector<f64>) -> DVector<f64>,
{
    let k1 = f(x, u);
    let k2 = f(&(x + &k1 * (0.5 * h)), u);
    let k3 = f(&(x + &k2 * (0.5 * h)), u);
    let k4 = f(&(x + &k3 * h), u);
    x + (k1 + (k2 + k3) * 2.0 + k4) * (h / 6.0)
}

/// Integrates over `duration` with `substeps` equal RK4 steps.
pub fn rk4_substeps<F>(
    f: F,
    x: &DVector<f64>,
    u: &DVector<f64>,
    duration: f64,
    substeps: usize,
) -> DVector<f64>
where
    F: Fn(&DVector<f64>, &DVector<f64>) -> DVector<f64>,
{
    let n = substeps.max(1);
    let h = duration / n as f64;
    let mut x = x.clone();
    for _ in 0..n {
        x = rk4(&f, &x, u, h);
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dvector;

    #[test]
    fn rk4_is_fourth_order_on_exponential_decay() {
        // ẋ = -x: exact x(1) = e^-1. Halving h divides the error by about 16.
        let f = |x: &DVector<f64>, _: &DVector<f64>| -x;
        let exact = (-1.0f64).exp();
        let err = |n| (rk4_substeps(f, &dvector![1.0], &dvector![], 1.0, n)[0] - exact).abs();
        let ratio = err(10) / err(20);
        assert!((ratio - 16.0).abs() < 1.0, "ratio {ratio}");
        assert!(err(20) < 1e-7);
    }

    #[test]
    fn euler_matches_its_definition() {
        let f = |x: &DVector<f64>, u: &DVector<f64>| dvector![x[1], u[0]];
        let x = euler(f, &dvector![1.0, 2.0], &dvector![3.0], 0.5);
        assert_eq!(x, dvector![2.0, 3.5]);
    }
}
