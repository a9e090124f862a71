//! DiffusionNet (Sharp, Attaiki, Crane, Ovsjanikov, ToG 2022) assembled
//! from [`crate::layers`], forward and backward:
//!
//! - a first linear layer C_in → C;
//! - N blocks, each: learned spectral diffusion of its input x, spatial
//!   gradient features of the diffused values, the concatenation
//!   `[x, diffused, features]` (n x 3C) through an MLP 3C → C → C → C
//!   (ReLU between the layers, dropout p = 0.5 before the second and the
//!   third while training), plus x (a residual connection);
//! - a last linear layer C → C_out.
//!
//! Parameters are initialised as PyTorch initialises `nn.Linear` (uniform
//! in ±1/√fan_in, weights and biases), the complex-linear maps without
//! bias, the diffusion times at 0, from a seed: a network is a function
//! of its seed.

pub use fmaps_simd::SplitMix;
use nalgebra::{DMatrix, DVector};

use crate::layers::{
    GradientFeatures, GradientFeaturesGrad, Gradients, Linear, LinearGrad, SpectralDiffusion,
    Spectrum,
};

/// The shape-dependent inputs of a forward pass.
#[derive(Debug, Clone, Copy)]
pub struct ShapeInput<'a> {
    /// Its spectral basis.
    pub spectrum: Spectrum<'a>,
    /// Its gradient operators.
    pub gradients: Gradients<'a>,
}

impl crate::ShapeOperators {
    /// The operators as a forward pass takes them.
    pub fn input(&self) -> ShapeInput<'_> {
        ShapeInput {
            spectrum: Spectrum {
                eigenvalues: &self.eigenvalues,
                eigenvectors: &self.eigenvectors,
                mass: &self.mass,
            },
            gradients: Gradients {
                x: &self.grad_x,
                y: &self.grad_y,
            },
        }
    }
}

/// Dropout while training: which entries are kept (the rest are zero, the
/// kept ones scaled by 1/(1 − p)).
#[derive(Debug, Clone, PartialEq)]
pub struct DropoutMask(DMatrix<f64>);

/// Dropout probability of the blocks' MLPs (the reference's).
pub const DROPOUT: f64 = 0.5;

impl DropoutMask {
    /// A mask of `rows` x `cols` from `rng`: each entry kept with
    /// probability 1 − [`DROPOUT`].
    pub fn draw(rows: usize, cols: usize, rng: &mut SplitMix) -> DropoutMask {
        let scale = 1.0 / (1.0 - DROPOUT);
        DropoutMask(DMatrix::from_fn(rows, cols, |_, _| {
            if rng.unit() >= DROPOUT { scale } else { 0.0 }
        }))
    }

    fn apply(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        x.component_mul(&self.0)
    }
}

/// A layer of uniform values in ±1/√fan_in (PyTorch's `nn.Linear`).
fn linear(inputs: usize, outputs: usize, bias: bool, rng: &mut SplitMix) -> Linear {
    let bound = 1.0 / (inputs as f64).sqrt();
    let weight = DMatrix::from_fn(outputs, inputs, |_, _| bound * rng.symmetric());
    let bias = DVector::from_fn(
        outputs,
        |_, _| if bias { bound * rng.symmetric() } else { 0.0 },
    );
    Linear { weight, bias }
}

/// One DiffusionNet block (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    /// The learned diffusion.
    pub diffusion: SpectralDiffusion,
    /// The spatial gradient features.
    pub features: GradientFeatures,
    /// The MLP's three layers (3C → C → C → C).
    pub mlp: [Linear; 3],
}

/// The gradients of a [`Block`]'s parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockGrad {
    /// d loss / d diffusion times.
    pub times: DVector<f64>,
    /// Of the gradient features.
    pub features: GradientFeaturesGrad,
    /// Of the MLP's layers.
    pub mlp: [LinearGrad; 3],
}

/// What a block's forward pass keeps for its backward pass.
#[derive(Debug, Clone)]
struct BlockTape {
    x: DMatrix<f64>,
    /// The input's spectral coefficients.
    spec: DMatrix<f64>,
    /// The gradient features' tape.
    feats: crate::layers::FeaturesTape,
    concat: DMatrix<f64>,
    /// The MLP's hidden pre-activations (after each of the first two
    /// layers) and the inputs of its last two layers (after ReLU and
    /// dropout).
    hidden: [DMatrix<f64>; 2],
    inputs: [DMatrix<f64>; 2],
    masks: Option<[DropoutMask; 2]>,
}

impl Block {
    /// A block of width `c` from `rng`.
    pub fn new(c: usize, rng: &mut SplitMix) -> Block {
        let features = GradientFeatures {
            a_re: linear(c, c, false, rng).weight,
            a_im: linear(c, c, false, rng).weight,
        };
        Block {
            diffusion: SpectralDiffusion {
                times: DVector::zeros(c),
            },
            features,
            mlp: [
                linear(3 * c, c, true, rng),
                linear(c, c, true, rng),
                linear(c, c, true, rng),
            ],
        }
    }

    fn forward_tape(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        masks: Option<[DropoutMask; 2]>,
    ) -> (DMatrix<f64>, BlockTape) {
        let (diffused, spec) = self.diffusion.forward_spectral(shape.spectrum, x);
        let feats = self.features.forward_tape(shape.gradients, &diffused);
        let (n, c) = x.shape();
        let mut concat = DMatrix::zeros(n, 3 * c);
        concat.columns_mut(0, c).copy_from(x);
        concat.columns_mut(c, c).copy_from(&diffused);
        concat.columns_mut(2 * c, c).copy_from(&feats.out);
        let h0 = self.mlp[0].forward(&concat);
        let mut in1 = h0.map(|v| v.max(0.0));
        if let Some(m) = &masks {
            in1 = m[0].apply(&in1);
        }
        let h1 = self.mlp[1].forward(&in1);
        let mut in2 = h1.map(|v| v.max(0.0));
        if let Some(m) = &masks {
            in2 = m[1].apply(&in2);
        }
        let out = self.mlp[2].forward(&in2) + x;
        let tape = BlockTape {
            x: x.clone(),
            spec,
            feats,
            concat,
            hidden: [h0, h1],
            inputs: [in1, in2],
            masks,
        };
        (out, tape)
    }

    /// The block's output (n x C); `masks`: dropout while training.
    pub fn forward(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        masks: Option<[DropoutMask; 2]>,
    ) -> DMatrix<f64> {
        self.forward_tape(shape, x, masks).0
    }

    fn backward_tape(
        &self,
        shape: ShapeInput<'_>,
        tape: &BlockTape,
        dy: &DMatrix<f64>,
    ) -> (DMatrix<f64>, BlockGrad) {
        let c = tape.x.ncols();
        let (mut d_in2, g2) = self.mlp[2].backward(&tape.inputs[1], dy);
        if let Some(m) = &tape.masks {
            d_in2 = m[1].apply(&d_in2);
        }
        let d_h1 = d_in2.zip_map(&tape.hidden[1], |d, h| if h > 0.0 { d } else { 0.0 });
        let (mut d_in1, g1) = self.mlp[1].backward(&tape.inputs[0], &d_h1);
        if let Some(m) = &tape.masks {
            d_in1 = m[0].apply(&d_in1);
        }
        let d_h0 = d_in1.zip_map(&tape.hidden[0], |d, h| if h > 0.0 { d } else { 0.0 });
        let (d_concat, g0) = self.mlp[0].backward(&tape.concat, &d_h0);
        let (d_feat_in, gf) = self.features.backward_tape(
            shape.gradients,
            &tape.feats,
            &d_concat.columns(2 * c, c).into_owned(),
        );
        let d_diffused = d_concat.columns(c, c) + d_feat_in;
        let (d_x_diff, times) =
            self.diffusion
                .backward_spectral(shape.spectrum, &tape.spec, &d_diffused);
        let dx = dy + d_concat.columns(0, c) + d_x_diff;
        (
            dx,
            BlockGrad {
                times,
                features: gf,
                mlp: [g0, g1, g2],
            },
        )
    }
}

/// DiffusionNet (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct DiffusionNet {
    /// C_in → C.
    pub first: Linear,
    /// The blocks.
    pub blocks: Vec<Block>,
    /// C → C_out.
    pub last: Linear,
}

/// The gradients of a [`DiffusionNet`]'s parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct DiffusionNetGrad {
    /// Of the first layer.
    pub first: LinearGrad,
    /// Of the blocks.
    pub blocks: Vec<BlockGrad>,
    /// Of the last layer.
    pub last: LinearGrad,
}

impl DiffusionNet {
    /// A network with `c_in` inputs, `width` channels, `blocks` blocks and
    /// `c_out` outputs (the reference's defaults for matching: width 128,
    /// 4 blocks, 256 outputs), initialised from `seed`.
    pub fn new(c_in: usize, width: usize, blocks: usize, c_out: usize, seed: u64) -> DiffusionNet {
        let mut rng = SplitMix(seed);
        DiffusionNet {
            first: linear(c_in, width, true, &mut rng),
            blocks: (0..blocks).map(|_| Block::new(width, &mut rng)).collect(),
            last: linear(width, c_out, true, &mut rng),
        }
    }

    /// The dropout masks of one training pass on `n` vertices.
    pub fn draw_masks(&self, n: usize, rng: &mut SplitMix) -> Vec<[DropoutMask; 2]> {
        let c = self.first.weight.nrows();
        self.blocks
            .iter()
            .map(|_| [DropoutMask::draw(n, c, rng), DropoutMask::draw(n, c, rng)])
            .collect()
    }

    /// The per-vertex features (n x C_out) of input features `x` (n x
    /// C_in); `masks` ([`draw_masks`](Self::draw_masks)): dropout while
    /// training, `None` to evaluate.
    pub fn forward(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        masks: Option<&[[DropoutMask; 2]]>,
    ) -> DMatrix<f64> {
        let mut h = self.first.forward(x);
        for (i, b) in self.blocks.iter().enumerate() {
            h = b.forward(shape, &h, masks.map(|m| m[i].clone()));
        }
        self.last.forward(&h)
    }

    /// The forward pass and, for `dy` = d loss / d output, the gradients
    /// of every parameter (and d loss / d input, returned first).
    pub fn backward(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        masks: Option<&[[DropoutMask; 2]]>,
        dy: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DiffusionNetGrad) {
        let (_, tape) = self.forward_tape(shape, x, masks);
        self.backward_tape(shape, x, &tape, dy)
    }

    /// The forward pass keeping what its backward pass needs (the
    /// output, and the tape for [`backward_tape`](Self::backward_tape)).
    pub fn forward_tape(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        masks: Option<&[[DropoutMask; 2]]>,
    ) -> (DMatrix<f64>, Tape) {
        let mut h = self.first.forward(x);
        let mut blocks = Vec::with_capacity(self.blocks.len());
        for (i, b) in self.blocks.iter().enumerate() {
            let (out, tape) = b.forward_tape(shape, &h, masks.map(|m| m[i].clone()));
            blocks.push(tape);
            h = out;
        }
        let out = self.last.forward(&h);
        (out, Tape { blocks, last: h })
    }

    /// The backward pass of a [`forward_tape`](Self::forward_tape) on the
    /// same shape and input `x`: d loss / d input and the parameters'
    /// gradients for `dy` = d loss / d output.
    pub fn backward_tape(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        tape: &Tape,
        dy: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DiffusionNetGrad) {
        let (mut d, last) = self.last.backward(&tape.last, dy);
        let mut blocks = Vec::with_capacity(self.blocks.len());
        for (b, t) in self.blocks.iter().zip(&tape.blocks).rev() {
            let (dx, g) = b.backward_tape(shape, t, &d);
            blocks.push(g);
            d = dx;
        }
        blocks.reverse();
        let (dx, first) = self.first.backward(x, &d);
        (
            dx,
            DiffusionNetGrad {
                first,
                blocks,
                last,
            },
        )
    }
}

/// What a training forward pass keeps for its backward pass.
#[derive(Debug, Clone)]
pub struct Tape {
    blocks: Vec<BlockTape>,
    /// The last layer's input.
    last: DMatrix<f64>,
}

/// A per-vertex feature network as training drives it: the losses and
/// the optimiser talk to this trait, so another network or another
/// backend (a framework, an f32 path) can take DiffusionNet's place.
pub trait FeatureNet: Sync {
    /// The random choices of one training pass (dropout masks).
    type Noise: Send + Sync;
    /// What a training forward pass keeps for its backward pass.
    type Tape: Send + Sync;
    /// The parameters' gradients.
    type Grad: Send;

    /// Draws the random choices of a training pass on `n` vertices.
    fn draw(&self, n: usize, rng: &mut SplitMix) -> Self::Noise;
    /// The features (n x outputs) of input `x`, with `noise` while
    /// training (`None` to evaluate), and the tape.
    fn forward_train(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        noise: Option<&Self::Noise>,
    ) -> (DMatrix<f64>, Self::Tape);
    /// The parameters' gradients for `dy` = d loss / d features.
    fn backward_train(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        tape: &Self::Tape,
        dy: &DMatrix<f64>,
    ) -> Self::Grad;
    /// `a += b`.
    fn add_grad(a: &mut Self::Grad, b: &Self::Grad);
    /// The parameters' values, in a fixed order.
    fn params_mut(&mut self) -> Vec<&mut [f64]>;
    /// The gradients, in the order of [`params_mut`](Self::params_mut).
    fn grad_groups_mut(g: &mut Self::Grad) -> Vec<&mut [f64]>;
}

impl FeatureNet for DiffusionNet {
    type Noise = Vec<[DropoutMask; 2]>;
    type Tape = Tape;
    type Grad = DiffusionNetGrad;

    fn draw(&self, n: usize, rng: &mut SplitMix) -> Self::Noise {
        self.draw_masks(n, rng)
    }

    fn forward_train(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        noise: Option<&Self::Noise>,
    ) -> (DMatrix<f64>, Tape) {
        self.forward_tape(shape, x, noise.map(Vec::as_slice))
    }

    fn backward_train(
        &self,
        shape: ShapeInput<'_>,
        x: &DMatrix<f64>,
        tape: &Tape,
        dy: &DMatrix<f64>,
    ) -> DiffusionNetGrad {
        self.backward_tape(shape, x, tape, dy).1
    }

    fn add_grad(a: &mut DiffusionNetGrad, b: &DiffusionNetGrad) {
        a.add(b);
    }

    fn params_mut(&mut self) -> Vec<&mut [f64]> {
        DiffusionNet::params_mut(self)
    }

    fn grad_groups_mut(g: &mut DiffusionNetGrad) -> Vec<&mut [f64]> {
        g.groups_mut()
    }
}

/// One parameter tensor of a network, by the name the reference
/// implementation's PyTorch `state_dict` gives it (`first_lin.weight`,
/// `block_0.diffusion.diffusion_time`, ...), with its shape.
#[derive(Debug, Clone)]
pub struct Param<'a> {
    /// The reference's name.
    pub name: String,
    /// The reference's shape: `[rows, columns]` of a weight (PyTorch's
    /// `out x in`), `[length]` of a vector.
    pub shape: Vec<usize>,
    /// The values, column-major (nalgebra's order).
    pub values: &'a [f64],
}

const MLP_NAMES: [&str; 3] = [
    "miniMLP_mlp_layer_000",
    "miniMLP_mlp_layer_001",
    "miniMLP_mlp_layer_002",
];

fn weight(name: String, m: &DMatrix<f64>) -> Param<'_> {
    Param {
        name,
        shape: vec![m.nrows(), m.ncols()],
        values: m.as_slice(),
    }
}

fn vector(name: String, v: &DVector<f64>) -> Param<'_> {
    Param {
        name,
        shape: vec![v.len()],
        values: v.as_slice(),
    }
}

impl DiffusionNet {
    /// Input channels.
    pub fn inputs(&self) -> usize {
        self.first.weight.ncols()
    }

    /// Width of the blocks.
    pub fn width(&self) -> usize {
        self.first.weight.nrows()
    }

    /// Output channels.
    pub fn outputs(&self) -> usize {
        self.last.weight.nrows()
    }

    /// The parameter tensors in the fixed order of the optimiser's
    /// groups: the first layer (weight, bias); per block the diffusion
    /// times, `A_re`, `A_im`, the MLP's weights and biases; the last
    /// layer.
    pub fn params(&self) -> Vec<Param<'_>> {
        let mut out = vec![
            weight("first_lin.weight".into(), &self.first.weight),
            vector("first_lin.bias".into(), &self.first.bias),
        ];
        for (i, b) in self.blocks.iter().enumerate() {
            out.push(vector(
                format!("block_{i}.diffusion.diffusion_time"),
                &b.diffusion.times,
            ));
            out.push(weight(
                format!("block_{i}.gradient_features.A_re.weight"),
                &b.features.a_re,
            ));
            out.push(weight(
                format!("block_{i}.gradient_features.A_im.weight"),
                &b.features.a_im,
            ));
            for (l, name) in b.mlp.iter().zip(MLP_NAMES) {
                out.push(weight(format!("block_{i}.mlp.{name}.weight"), &l.weight));
                out.push(vector(format!("block_{i}.mlp.{name}.bias"), &l.bias));
            }
        }
        out.push(weight("last_lin.weight".into(), &self.last.weight));
        out.push(vector("last_lin.bias".into(), &self.last.bias));
        out
    }

    /// The parameter tensors' values, mutable, in the order of
    /// [`params`](Self::params).
    pub fn params_mut(&mut self) -> Vec<&mut [f64]> {
        let mut out: Vec<&mut [f64]> = vec![
            self.first.weight.as_mut_slice(),
            self.first.bias.as_mut_slice(),
        ];
        for b in &mut self.blocks {
            out.push(b.diffusion.times.as_mut_slice());
            out.push(b.features.a_re.as_mut_slice());
            out.push(b.features.a_im.as_mut_slice());
            for l in &mut b.mlp {
                out.push(l.weight.as_mut_slice());
                out.push(l.bias.as_mut_slice());
            }
        }
        out.push(self.last.weight.as_mut_slice());
        out.push(self.last.bias.as_mut_slice());
        out
    }
}

impl DiffusionNetGrad {
    /// The gradients, mutable, in the order of [`DiffusionNet::params`].
    pub fn groups_mut(&mut self) -> Vec<&mut [f64]> {
        let mut out: Vec<&mut [f64]> = vec![
            self.first.weight.as_mut_slice(),
            self.first.bias.as_mut_slice(),
        ];
        for b in &mut self.blocks {
            out.push(b.times.as_mut_slice());
            out.push(b.features.a_re.as_mut_slice());
            out.push(b.features.a_im.as_mut_slice());
            for l in &mut b.mlp {
                out.push(l.weight.as_mut_slice());
                out.push(l.bias.as_mut_slice());
            }
        }
        out.push(self.last.weight.as_mut_slice());
        out.push(self.last.bias.as_mut_slice());
        out
    }

    /// Adds `other` (the gradients of another term of the same loss).
    pub fn add(&mut self, other: &DiffusionNetGrad) {
        let mut theirs = other.clone();
        for (a, b) in self.groups_mut().into_iter().zip(theirs.groups_mut()) {
            for (x, y) in a.iter_mut().zip(b.iter()) {
                *x += y;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ShapeOperators;
    use crate::testing::random;

    fn inner(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
        a.component_mul(b).sum()
    }

    /// The whole network's gradients against central differences of its
    /// forward pass (with fixed dropout masks and non-zero diffusion
    /// times), along random directions of the input, of the first
    /// layer's weights, of a block's times and complex map and of an MLP
    /// layer: relative error below 1e-6 (f64, step 1e-5).
    #[test]
    fn network_backward_matches_finite_differences() {
        let ops = ShapeOperators::compute(&fmaps_shapes::creature_pair(1).source, 10).unwrap();
        let shape = ops.input();
        let n = ops.mass.len();
        let mut net = DiffusionNet::new(3, 6, 2, 4, 7);
        for (i, b) in net.blocks.iter_mut().enumerate() {
            b.diffusion.times = DVector::from_fn(6, |c, _| 0.002 * (1 + c + i) as f64);
        }
        let masks = net.draw_masks(n, &mut SplitMix(11));
        let x = random(n, 3, 1);
        let r = random(n, 4, 2);
        let loss =
            |net: &DiffusionNet, x: &DMatrix<f64>| inner(&r, &net.forward(shape, x, Some(&masks)));
        let (dx, g) = net.backward(shape, &x, Some(&masks), &r);
        let h = 1e-5;
        let check = |analytic: f64, f: &dyn Fn(f64) -> f64, what: &str| {
            let numeric = (f(h) - f(-h)) / (2.0 * h);
            let scale = analytic.abs().max(numeric.abs()).max(1e-8);
            assert!(
                (analytic - numeric).abs() / scale < 1e-6,
                "{what}: analytic {analytic}, finite difference {numeric}"
            );
        };
        let ex = random(n, 3, 3);
        check(inner(&dx, &ex), &|t| loss(&net, &(&x + &ex * t)), "input");
        let ew = random(6, 3, 4);
        check(
            inner(&g.first.weight, &ew),
            &|t| {
                let mut m = net.clone();
                m.first.weight += &ew * t;
                loss(&m, &x)
            },
            "first weights",
        );
        let et = random(6, 1, 5);
        check(
            g.blocks[0].times.dot(&et.column(0)),
            &|t| {
                let mut m = net.clone();
                m.blocks[0].diffusion.times += et.column(0) * t;
                loss(&m, &x)
            },
            "block 0 times",
        );
        let ea = random(6, 6, 6);
        check(
            inner(&g.blocks[1].features.a_im, &ea),
            &|t| {
                let mut m = net.clone();
                m.blocks[1].features.a_im += &ea * t;
                loss(&m, &x)
            },
            "block 1 A_im",
        );
        let em = random(6, 18, 8);
        check(
            inner(&g.blocks[1].mlp[0].weight, &em),
            &|t| {
                let mut m = net.clone();
                m.blocks[1].mlp[0].weight += &em * t;
                loss(&m, &x)
            },
            "block 1 MLP layer 0",
        );
        let eb = random(4, 1, 9);
        check(
            g.last.bias.dot(&eb.column(0)),
            &|t| {
                let mut m = net.clone();
                m.last.bias += eb.column(0) * t;
                loss(&m, &x)
            },
            "last bias",
        );
    }

    /// A network is a function of its seed; dropout keeps about half the
    /// entries, scaled by two.
    #[test]
    fn seeds_and_dropout() {
        assert_eq!(
            DiffusionNet::new(3, 8, 2, 5, 1),
            DiffusionNet::new(3, 8, 2, 5, 1)
        );
        assert_ne!(
            DiffusionNet::new(3, 8, 2, 5, 1),
            DiffusionNet::new(3, 8, 2, 5, 2)
        );
        let m = DropoutMask::draw(200, 50, &mut SplitMix(3));
        let kept = m.0.iter().filter(|&&v| v == 2.0).count();
        assert_eq!(kept + m.0.iter().filter(|&&v| v == 0.0).count(), 10_000);
        // Binomial(10000, 1/2): within 4 standard deviations (50 each).
        assert!((kept as i64 - 5000).abs() < 200, "{kept}");
    }
}
