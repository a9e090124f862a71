//! Training steps: Adam (Kingma and Ba, ICLR 2015, with bias correction,
//! as PyTorch's `torch.optim.Adam` without weight decay) and clipping of
//! the gradients' global norm (PyTorch's `clip_grad_norm_`).
//!
//! Parameters and gradients are flat slices; a model hands its parameter
//! groups over in a fixed order, each group keeping its own moments.

/// Adam's hyper-parameters and moments.
#[derive(Debug, Clone, PartialEq)]
pub struct Adam {
    /// Learning rate (ULRSSM: 1e-3).
    pub lr: f64,
    /// Decay of the first moment (0.9).
    pub beta1: f64,
    /// Decay of the second moment (0.999).
    pub beta2: f64,
    /// Added to the second moment's root (1e-8).
    pub eps: f64,
    /// Steps taken.
    pub steps: u64,
    /// First and second moments per parameter group.
    moments: Vec<(Vec<f64>, Vec<f64>)>,
}

impl Adam {
    /// Adam with learning rate `lr` and the usual β₁ = 0.9, β₂ = 0.999,
    /// ε = 1e-8.
    pub fn new(lr: f64) -> Adam {
        Adam {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            steps: 0,
            moments: Vec::new(),
        }
    }

    /// The first and second moments of each parameter group (empty
    /// before its first update).
    pub fn moments(&self) -> &[(Vec<f64>, Vec<f64>)] {
        &self.moments
    }

    /// Restores moments saved from [`moments`](Self::moments) (with
    /// [`steps`](Self::steps)), to continue exactly.
    pub fn set_moments(&mut self, moments: Vec<(Vec<f64>, Vec<f64>)>) {
        self.moments = moments;
    }

    /// Counts one step: call once per step, before updating its groups.
    pub fn begin_step(&mut self) {
        self.steps += 1;
    }

    /// Updates the parameter group `group` (its index in the model's
    /// order) from its gradients: `p −= lr · m̂ / (√v̂ + ε)` with the
    /// bias-corrected moments `m̂ = m / (1 − β₁ᵗ)`, `v̂ = v / (1 − β₂ᵗ)`.
    ///
    /// # Panics
    ///
    /// When `params` and `grads` differ in length, or the group changed
    /// size since its first step (a programming error of the caller).
    pub fn update(&mut self, group: usize, params: &mut [f64], grads: &[f64]) {
        assert_eq!(
            params.len(),
            grads.len(),
            "group {group}: parameters and gradients"
        );
        if self.moments.len() <= group {
            self.moments.resize_with(group + 1, Default::default);
        }
        let (m, v) = &mut self.moments[group];
        if m.is_empty() {
            *m = vec![0.0; params.len()];
            *v = vec![0.0; params.len()];
        }
        assert_eq!(m.len(), params.len(), "group {group} changed size");
        let t = self.steps.max(1) as i32;
        let (c1, c2) = (1.0 - self.beta1.powi(t), 1.0 - self.beta2.powi(t));
        for i in 0..params.len() {
            let g = grads[i];
            m[i] = self.beta1 * m[i] + (1.0 - self.beta1) * g;
            v[i] = self.beta2 * v[i] + (1.0 - self.beta2) * g * g;
            params[i] -= self.lr * (m[i] / c1) / ((v[i] / c2).sqrt() + self.eps);
        }
    }
}

/// Scales the gradient groups so that their global L² norm is at most
/// `max_norm` (unchanged when it is already); returns the norm before.
pub fn clip_grad_norm(groups: &mut [&mut [f64]], max_norm: f64) -> f64 {
    let norm = groups
        .iter()
        .flat_map(|g| g.iter())
        .map(|x| x * x)
        .sum::<f64>()
        .sqrt();
    if norm > max_norm {
        let s = max_norm / (norm + 1e-6);
        for g in groups.iter_mut() {
            for x in g.iter_mut() {
                *x *= s;
            }
        }
    }
    norm
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Adam's first step moves every parameter by `lr` against the sign
    /// of its gradient (m̂ = g, v̂ = g²), whatever the gradient's size.
    #[test]
    fn the_first_step_is_lr_times_the_sign() {
        let mut adam = Adam::new(0.01);
        let mut p = vec![1.0, 2.0, -3.0];
        adam.begin_step();
        adam.update(0, &mut p, &[1e3, -1e-3, 5.0]);
        let want = [0.99, 2.01, -3.01];
        for (a, b) in p.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{p:?}");
        }
    }

    /// On `f(x) = Σ a_i (x_i − c_i)²` Adam reaches the minimum.
    #[test]
    fn adam_minimises_a_quadratic() {
        let (a, c) = ([1.0, 10.0, 0.1], [3.0, -2.0, 0.5]);
        let mut x = vec![0.0; 3];
        let mut adam = Adam::new(0.05);
        for _ in 0..3000 {
            let g: Vec<f64> = (0..3).map(|i| 2.0 * a[i] * (x[i] - c[i])).collect();
            adam.begin_step();
            adam.update(0, &mut x, &g);
        }
        for i in 0..3 {
            assert!((x[i] - c[i]).abs() < 1e-3, "{x:?}");
        }
    }

    /// Clipping scales all groups by the same factor to the bound, and
    /// leaves small gradients alone.
    #[test]
    fn clipping_bounds_the_global_norm() {
        let (mut g1, mut g2) = (vec![3.0, 0.0], vec![0.0, 4.0]);
        let before = clip_grad_norm(&mut [&mut g1, &mut g2], 1.0);
        assert_eq!(before, 5.0);
        let after = (g1[0].powi(2) + g2[1].powi(2)).sqrt();
        assert!((after - 1.0).abs() < 1e-6);
        assert!((g1[0] / g2[1] - 0.75).abs() < 1e-12);
        let mut small = vec![0.1, 0.2];
        clip_grad_norm(&mut [&mut small], 1.0);
        assert_eq!(small, [0.1, 0.2]);
    }
}
