//! Jacobian rows of the norm model `w·(n − k/n − 1)`, `n = |R(x − b)|` ([`super::norm_lm`]),
//! and the normal equations `JᵀJ`, `Jᵀr` summed from them without holding `J` (45 + 9
//! multiply-adds a sample), on two threads for large problems.

use super::{Mat3, Vec3};

/// `JᵀJ` (upper triangle, row-major, 45 entries) and `Jᵀr` over all samples. Problems of at
/// least [`PARALLEL_MIN_SAMPLES`] are summed in two halves on two threads; the split depends
/// only on the number of samples, so the result is the same on any machine.
pub(super) fn summed_normal_equations(
    r: &Mat3,
    b: &Vec3,
    points: &[Vec3],
    weights: &[f64],
    tangential: &[f64],
    res: &nalgebra::DVector<f64>,
) -> ([f64; 45], [f64; 9]) {
    let res = res.as_slice();
    let n = points
        .len()
        .min(weights.len())
        .min(tangential.len())
        .min(res.len());
    let sums = |range: std::ops::Range<usize>| {
        normal_sums(
            r,
            b,
            &points[range.clone()],
            &weights[range.clone()],
            &tangential[range.clone()],
            &res[range],
        )
    };
    if n < PARALLEL_MIN_SAMPLES {
        return sums(0..n);
    }
    let half = n / 2;
    let ((mut upper, mut grad), (second_upper, second_grad)) = std::thread::scope(|scope| {
        let second = scope.spawn(|| sums(half..n));
        let first = sums(0..half);
        let second = second
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (first, second)
    });
    upper
        .iter_mut()
        .zip(second_upper)
        .for_each(|(a, b)| *a += b);
    grad.iter_mut().zip(second_grad).for_each(|(a, b)| *a += b);
    (upper, grad)
}

/// Samples from which the normal equations are summed on two threads: below this a pass takes
/// well under a millisecond and starting a thread would cost a noticeable part of it.
const PARALLEL_MIN_SAMPLES: usize = 100_000;

/// The upper triangle of `JᵀJ` (row-major, 45 entries) and `Jᵀr` over the given samples.
fn normal_sums(
    r: &Mat3,
    b: &Vec3,
    points: &[Vec3],
    weights: &[f64],
    tangential: &[f64],
    res: &[f64],
) -> ([f64; 45], [f64; 9]) {
    let mut upper = [0.0; 45];
    let mut grad = [0.0; 9];
    for (((x, w), k), ri) in points.iter().zip(weights).zip(tangential).zip(res) {
        let row = jacobian_row(r, b, x, *w, *k);
        let mut at = 0;
        for i in 0..9 {
            grad[i] += row[i] * ri;
            for j in i..9 {
                upper[at] += row[i] * row[j];
                at += 1;
            }
        }
    }
    (upper, grad)
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
    fn two_thread_sums_equal_one_pass_up_to_summation_order() {
        let n = PARALLEL_MIN_SAMPLES + 1;
        let points: Vec<Vec3> = (0..n)
            .map(|i| {
                let t = i as f64;
                Vec3::new((0.37 * t).sin(), (0.11 * t).cos(), (0.05 * t).sin() + 0.2)
            })
            .collect();
        let weights = vec![1.0; n];
        let tangential = vec![1e-4; n];
        let res = nalgebra::DVector::from_fn(n, |i, _| (0.7 * i as f64).sin() * 1e-2);
        let r = Mat3::new(1.1, 0.02, -0.03, 0.0, 0.9, 0.01, 0.0, 0.0, 1.05);
        let b = Vec3::new(0.1, -0.2, 0.05);
        let (upper, grad) = summed_normal_equations(&r, &b, &points, &weights, &tangential, &res);
        let (one_upper, one_grad) =
            normal_sums(&r, &b, &points, &weights, &tangential, res.as_slice());
        // Two partial sums of 5·10⁴ terms added, against one running sum: rounding only.
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
