//! Jacobian rows of the norm model `w·(n − k/n − 1)`, `n = |R(x − b)|` ([`super::norm_lm`]),
//! and the normal equations `JᵀJ`, `Jᵀr` summed from them without holding `J` (45 + 9
//! multiply-adds a sample), together with the residuals in the same pass, on two threads for
//! large problems.
//!
//! The sums run over blocks of [`LANES`] samples with one accumulator per lane, so the 54
//! multiply-adds of a sample are independent vector operations (no dependency chain through
//! one running sum); the lanes are added at the end. Only the order of the additions differs
//! from a plain running sum, so the results agree with it to rounding.

use super::{Mat3, Vec3};

/// The samples of one evaluation: centred, scaled points with their weights `w` and
/// tangential-noise corrections `k`.
#[derive(Clone, Copy)]
pub(super) struct NormSamples<'a> {
    /// Centred, scaled points.
    pub points: &'a [Vec3],
    /// Weight `w` of each point's residual.
    pub weights: &'a [f64],
    /// Correction `k` of each point's norm (`n − k/n`).
    pub tangential: &'a [f64],
}

impl NormSamples<'_> {
    /// The number of samples.
    pub fn len(&self) -> usize {
        self.points
            .len()
            .min(self.weights.len())
            .min(self.tangential.len())
    }

    /// The samples in `range`.
    pub fn range(&self, range: std::ops::Range<usize>) -> Self {
        Self {
            points: &self.points[range.clone()],
            weights: &self.weights[range.clone()],
            tangential: &self.tangential[range],
        }
    }
}

/// The residual `w·(n − k/n − 1)` of a point whose calibrated norm is `n`; `−w` at the centre.
#[inline(always)]
pub(super) fn norm_residual(n: f64, w: f64, k: f64) -> f64 {
    if n > 0.0 {
        w * ((n - k / n) - 1.0)
    } else {
        -w
    }
}

/// `JᵀJ` (upper triangle, row-major, 45 entries) and `Jᵀr` over all samples, with the residual
/// of every sample written to `res` (which must hold one entry per sample). Problems of at
/// least [`PARALLEL_MIN_SAMPLES`] are summed in two halves on two threads; the split depends
/// only on the number of samples, so the result is the same on any machine.
///
/// With `hessian_stride > 1`, `JᵀJ` is summed over every `hessian_stride`-th block of samples
/// only and scaled up to all of them (`Jᵀr` and the residuals stay exact): see
/// [`hessian_stride`].
pub(super) fn residuals_and_normal_equations(
    r: &Mat3,
    b: &Vec3,
    samples: NormSamples<'_>,
    res: &mut [f64],
    hessian_stride: usize,
) -> ([f64; 45], [f64; 9]) {
    let n = samples.len().min(res.len());
    in_two_halves(
        n,
        &mut res[..n],
        |range, part| block_sums(r, b, samples.range(range), part, hessian_stride),
        |(mut upper, mut grad), (second_upper, second_grad)| {
            upper
                .iter_mut()
                .zip(second_upper)
                .for_each(|(a, b)| *a += b);
            grad.iter_mut().zip(second_grad).for_each(|(a, b)| *a += b);
            (upper, grad)
        },
    )
}

/// `part` over samples `0..n` (with `out`, one entry per sample or empty, cut to match), in two
/// halves on two threads from [`PARALLEL_MIN_SAMPLES`] on, the halves joined by `add`. The split
/// depends only on `n`, so the result is the same on any machine.
pub(super) fn in_two_halves<T: Send>(
    n: usize,
    out: &mut [f64],
    part: impl Fn(std::ops::Range<usize>, &mut [f64]) -> T + Sync,
    add: impl FnOnce(T, T) -> T,
) -> T {
    if n < PARALLEL_MIN_SAMPLES {
        return part(0..n, out);
    }
    let half = n / 2;
    let (first_out, second_out) = out.split_at_mut(half.min(out.len()));
    let (first, second) = std::thread::scope(|scope| {
        let second = scope.spawn(|| part(half..n, second_out));
        let first = part(0..half, first_out);
        let second = second
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (first, second)
    });
    add(first, second)
}

/// Samples from which the normal equations are summed on two threads: below this a pass takes
/// well under a millisecond and starting a thread would cost a noticeable part of it.
const PARALLEL_MIN_SAMPLES: usize = 100_000;

/// Samples per block: four `f64` lanes fill a 256-bit vector, two 128-bit ones.
pub(super) const LANES: usize = 4;

/// Samples that steer the iterations of a large fit by default (see [`hessian_stride`]).
pub(super) const ITERATION_SAMPLES: usize = 1 << 16;

/// The stride of blocks over which the iterations of a fit of `n` samples sum `JᵀJ`, for about
/// `samples` of them spread evenly over the data: every block up to twice that (or with
/// `None`). The iterations converge to the root of the exact `Jᵀr`, which alone decides the
/// solution; `JᵀJ` only sets the step, and a sum over `m` samples is within about `√(9/m)`
/// (≈ 1 % for 2¹⁶) of the full one, so each step still gains about two digits (a Newton step
/// with a 1 % error in its matrix). The covariance, the leverages and the condition number are
/// taken from a full sum at the solution.
pub(super) fn hessian_stride(n: usize, samples: Option<usize>) -> usize {
    match samples {
        // Every `n/m`-th block of `LANES` samples: `m` samples in all.
        Some(m) if m > 0 && n >= 2 * m => n / m,
        _ => 1,
    }
}

/// The upper triangle of `JᵀJ` and `Jᵀr` over the given samples, block by block with one
/// accumulator per lane; the residuals go to `res` (as long as the samples). `JᵀJ` over every
/// `hessian_stride`-th block only, scaled by the ratio of all blocks to those summed.
fn block_sums(
    r: &Mat3,
    b: &Vec3,
    samples: NormSamples<'_>,
    res: &mut [f64],
    hessian_stride: usize,
) -> ([f64; 45], [f64; 9]) {
    let stride = hessian_stride.max(1);
    let mut upper = [[0.0; LANES]; 45];
    let mut grad = [[0.0; LANES]; 9];
    let n = samples.len().min(res.len());
    let (mut blocks, mut summed) = (0usize, 0usize);
    for_each_block(r, b, samples.range(0..n), |start, valid, block| {
        let (rows, block_res) = (&block.rows, &block.res);
        res[start..start + valid].copy_from_slice(&block_res[..valid]);
        for i in 0..9 {
            for lane in 0..LANES {
                grad[i][lane] += rows[i][lane] * block_res[lane];
            }
        }
        if blocks % stride == 0 {
            let mut at = 0;
            for i in 0..9 {
                for j in i..9 {
                    for lane in 0..LANES {
                        upper[at][lane] += rows[i][lane] * rows[j][lane];
                    }
                    at += 1;
                }
            }
            summed += 1;
        }
        blocks += 1;
    });
    let scale = if summed == 0 {
        0.0
    } else {
        blocks as f64 / summed as f64
    };
    (
        upper.map(|lanes| lanes.iter().sum::<f64>() * scale),
        grad.map(|lanes| lanes.iter().sum()),
    )
}

/// Calls `f(start, valid, block)` for each block of [`LANES`] samples (the last may hold fewer,
/// `valid`), `start` the index of its first sample.
#[inline(always)]
pub(super) fn for_each_block(
    r: &Mat3,
    b: &Vec3,
    samples: NormSamples<'_>,
    mut f: impl FnMut(usize, usize, &Block),
) {
    let n = samples.len();
    let mut start = 0;
    while start < n {
        let valid = LANES.min(n - start);
        f(
            start,
            valid,
            &block_rows(r, b, samples.range(start..start + valid)),
        );
        start += valid;
    }
}

/// Up to [`LANES`] samples evaluated together, one lane each.
pub(super) struct Block {
    /// `u = x − b` per axis.
    pub u: [[f64; LANES]; 3],
    /// The calibrated direction `v̂ = R(x − b)/n` per axis (zero at the centre).
    pub direction: [[f64; LANES]; 3],
    /// `1/n` (zero at the centre).
    pub inverse_norm: [f64; LANES],
    /// The norm `n = |R(x − b)|`.
    pub norm: [f64; LANES],
    /// `∂r/∂n = w(1 + k/n²)`.
    pub slope: [f64; LANES],
    /// The weight `w`.
    pub weight: [f64; LANES],
    /// Jacobian rows, `rows[c][lane]` (as [`jacobian_row`] up to rounding).
    pub rows: [[f64; LANES]; 9],
    /// Residuals ([`norm_residual`]).
    pub res: [f64; LANES],
}

/// Up to [`LANES`] samples, computed lane by lane so that every operation is one vector
/// operation. Lanes past the samples have weight 0: zero rows and residuals.
#[inline(always)]
fn block_rows(r: &Mat3, b: &Vec3, samples: NormSamples<'_>) -> Block {
    let mut u = [[0.0; LANES]; 3];
    let mut w = [0.0; LANES];
    let mut k = [0.0; LANES];
    for (lane, ((x, wi), ki)) in samples
        .points
        .iter()
        .zip(samples.weights)
        .zip(samples.tangential)
        .take(LANES)
        .enumerate()
    {
        for axis in 0..3 {
            u[axis][lane] = x[axis] - b[axis];
        }
        w[lane] = *wi;
        k[lane] = *ki;
    }
    let mut block = Block {
        u,
        direction: [[0.0; LANES]; 3],
        inverse_norm: [0.0; LANES],
        norm: [0.0; LANES],
        slope: [0.0; LANES],
        weight: w,
        rows: [[0.0; LANES]; 9],
        res: [0.0; LANES],
    };
    let rows = &mut block.rows;
    for lane in 0..LANES {
        let (ux, uy, uz) = (u[0][lane], u[1][lane], u[2][lane]);
        let v0 = r[(0, 0)] * ux + r[(0, 1)] * uy + r[(0, 2)] * uz;
        let v1 = r[(1, 0)] * ux + r[(1, 1)] * uy + r[(1, 2)] * uz;
        let v2 = r[(2, 0)] * ux + r[(2, 1)] * uy + r[(2, 2)] * uz;
        let n = (v0 * v0 + v1 * v1 + v2 * v2).sqrt();
        block.res[lane] = norm_residual(n, w[lane], k[lane]);
        // At the centre (n = 0) the row is zero, as in `jacobian_row`.
        let inv = if n > 0.0 { 1.0 / n } else { 0.0 };
        // d(n − k/n)/dn = 1 + k/n².
        let scale = w[lane] * (1.0 + k[lane] * inv * inv);
        let (h0, h1, h2) = (v0 * inv, v1 * inv, v2 * inv);
        block.norm[lane] = n;
        block.inverse_norm[lane] = inv;
        block.slope[lane] = scale;
        block.direction[0][lane] = h0;
        block.direction[1][lane] = h1;
        block.direction[2][lane] = h2;
        let (s0, s1, s2) = (scale * h0, scale * h1, scale * h2);
        rows[0][lane] = s0 * ux;
        rows[1][lane] = s0 * uy;
        rows[2][lane] = s0 * uz;
        rows[3][lane] = s1 * uy;
        rows[4][lane] = s1 * uz;
        rows[5][lane] = s2 * uz;
        // ∂n/∂b = −Rᵀv̂.
        rows[6][lane] = -(r[(0, 0)] * s0 + r[(1, 0)] * s1 + r[(2, 0)] * s2);
        rows[7][lane] = -(r[(0, 1)] * s0 + r[(1, 1)] * s1 + r[(2, 1)] * s2);
        rows[8][lane] = -(r[(0, 2)] * s0 + r[(1, 2)] * s1 + r[(2, 2)] * s2);
    }
    block
}

/// One row of the Jacobian: the derivative of `w·(n − k/n − 1)`, `n = |R(x − b)|`, with respect
/// to `R11 R12 R13 R22 R23 R33 b1 b2 b3`. Zero at the centre, where the norm is not
/// differentiable.
#[inline(always)]
pub(super) fn jacobian_row(r: &Mat3, b: &Vec3, x: &Vec3, w: f64, k: f64) -> [f64; 9] {
    let u = x - b;
    let v = r * u;
    let n = v.norm();
    if n == 0.0 {
        return [0.0; 9];
    }
    // d(n − k/n)/dn = 1 + k/n².
    let w = w * (1.0 + k / (n * n));
    let vh = v / n;
    let db = -(r.transpose() * vh);
    [
        w * vh[0] * u[0],
        w * vh[0] * u[1],
        w * vh[0] * u[2],
        w * vh[1] * u[1],
        w * vh[1] * u[2],
        w * vh[2] * u[2],
        w * db[0],
        w * db[1],
        w * db[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_thread_lane_sums_equal_one_running_sum_up_to_rounding() {
        // Two threads, and a last block with fewer samples than lanes.
        let n = PARALLEL_MIN_SAMPLES + 2 * LANES + 3;
        let points: Vec<Vec3> = (0..n)
            .map(|i| {
                let t = i as f64;
                Vec3::new((0.37 * t).sin(), (0.11 * t).cos(), (0.05 * t).sin() + 0.2)
            })
            .collect();
        let weights: Vec<f64> = (0..n)
            .map(|i| 1.0 + 0.3 * (0.13 * i as f64).cos())
            .collect();
        let tangential = vec![1e-4; n];
        let r = Mat3::new(1.1, 0.02, -0.03, 0.0, 0.9, 0.01, 0.0, 0.0, 1.05);
        let b = Vec3::new(0.1, -0.2, 0.05);
        let samples = NormSamples {
            points: &points,
            weights: &weights,
            tangential: &tangential,
        };
        let mut res = vec![f64::NAN; n];
        let (upper, grad) = residuals_and_normal_equations(&r, &b, samples, &mut res, 1);
        // One running sum over the rows of the reference Jacobian.
        let mut one_upper = [0.0; 45];
        let mut one_grad = [0.0; 9];
        for (i, x) in points.iter().enumerate() {
            let row = jacobian_row(&r, &b, x, weights[i], tangential[i]);
            let ri = norm_residual((r * (x - b)).norm(), weights[i], tangential[i]);
            // Same formula, |R(x − b)| summed in the same order: equal up to the last bit or two.
            assert!(
                (res[i] - ri).abs() <= 4.0 * f64::EPSILON * ri.abs().max(1.0),
                "residual {i}"
            );
            let mut at = 0;
            for c in 0..9 {
                one_grad[c] += row[c] * ri;
                for d in c..9 {
                    one_upper[at] += row[c] * row[d];
                    at += 1;
                }
            }
        }
        // Two threads of lane-wise partial sums added, against one running sum of 10⁵ terms:
        // rounding only (relative error ≲ 10⁵·ε ≈ 2e-11).
        for (two, one) in upper
            .iter()
            .chain(&grad)
            .zip(one_upper.iter().chain(&one_grad))
        {
            assert!(
                (two - one).abs() <= 1e-9 * one.abs().max(1.0),
                "{two} vs {one}"
            );
        }
    }
}
