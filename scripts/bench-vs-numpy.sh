#!/usr/bin/env bash
# Li's ellipsoid fit on 10⁶ points: imucal (Rust, one thread) against numpy's algebra for the
# same fit (design matrix, S = DᵀD, the reduced 6×6 eigenproblem), on one shared array, in one
# run. Sets up its own Python environment (numpy from PyPI) in target/bench-vs-numpy.
# Usage: scripts/bench-vs-numpy.sh [POINTS] [REPEATS]
set -euo pipefail
cd "$(dirname "$0")/.."
points=${1:-1000000}
repeats=${2:-21}
work=${CARGO_TARGET_DIR:-target}/bench-vs-numpy
mkdir -p "$work"
if [ ! -x "$work/venv/bin/python" ]; then
    python3 -m venv "$work/venv"
    "$work/venv/bin/pip" install --quiet numpy
fi
py="$work/venv/bin/python"
# Absolute: cargo runs the bench from the package directory.
array="$(cd "$work" && pwd)/points-$points.f64"

# One array for both: a tilted, offset ellipsoid with noise, seeded.
"$py" - "$points" "$array" <<'PY'
import sys
import numpy as np
n, path = int(sys.argv[1]), sys.argv[2]
rng = np.random.default_rng(7)
u = rng.normal(size=(n, 3))
u /= np.linalg.norm(u, axis=1, keepdims=True)
soft = np.array([[1.2, 0.05, -0.03], [0.0, 0.9, 0.04], [0.0, 0.0, 1.05]])
x = 50.0 * u @ soft.T + np.array([80.0, -35.0, 120.0]) + rng.normal(scale=0.5, size=(n, 3))
x.astype("<f8").tofile(path)
PY

# numpy: the same algebra (mean subtraction and scaling, D, S = DᵀD, Li & Griffiths' reduced
# eigenproblem, the linear part); median of REPEATS runs, array already in memory.
numpy_ms=$("$py" - "$array" "$repeats" <<'PY'
import sys, time
import numpy as np
x = np.fromfile(sys.argv[1], dtype="<f8").reshape(-1, 3)
repeats = int(sys.argv[2])
C1 = np.array([[-1, 1, 1, 0, 0, 0], [1, -1, 1, 0, 0, 0], [1, 1, -1, 0, 0, 0],
               [0, 0, 0, -4, 0, 0], [0, 0, 0, 0, -4, 0], [0, 0, 0, 0, 0, -4]], dtype=float)
def li(x):
    c = x.mean(axis=0)
    q = x - c
    s = np.sqrt((q * q).sum(axis=1).mean())
    q = q / s
    X, Y, Z = q[:, 0], q[:, 1], q[:, 2]
    D = np.column_stack([X*X, Y*Y, Z*Z, 2*Y*Z, 2*X*Z, 2*X*Y, 2*X, 2*Y, 2*Z, np.ones(len(q))])
    S = D.T @ D
    S11, S12, S22 = S[:6, :6], S[:6, 6:], S[6:, 6:]
    S22i = np.linalg.inv(S22)
    E = np.linalg.inv(C1) @ (S11 - S12 @ S22i @ S12.T)
    w, V = np.linalg.eig(E)
    v1 = np.real(V[:, np.argmax(np.real(w))])
    v2 = -S22i @ S12.T @ v1
    v = np.concatenate([v1, v2])
    M = np.array([[v[0], v[5], v[4]], [v[5], v[1], v[3]], [v[4], v[3], v[2]]])
    b = -np.linalg.solve(M, v[6:9])
    return c + b * s
times = []
cpu0 = time.process_time()
for _ in range(repeats):
    t0 = time.perf_counter()
    centre = li(x)
    times.append((time.perf_counter() - t0) * 1e3)
print("numpy_li_centre", *("%.9f" % v for v in centre), file=sys.stderr)
print("numpy_li_cpu_ms %.2f (all threads)" % ((time.process_time() - cpu0) * 1e3 / repeats), file=sys.stderr)
print("%.2f" % sorted(times)[len(times) // 2])
PY
)

rust_out=$(IMUCAL_LI_POINTS="$array" IMUCAL_LI_REPEATS="$repeats" \
    cargo bench --quiet -p imucal --bench li_vs_numpy 2>/dev/null)
echo "$rust_out" | grep -E "rust_li_centre|rust_li_cpu_ms"
rust_ms=$(echo "$rust_out" | awk '/^rust_li_ms/ {print $2}')
echo "points $points, median of $repeats runs each"
echo "numpy  Li fit: $numpy_ms ms"
echo "imucal Li fit: $rust_ms ms"
awk -v n="$numpy_ms" -v r="$rust_ms" 'BEGIN { printf "ratio numpy/imucal: %.1f×\n", n / r }'
