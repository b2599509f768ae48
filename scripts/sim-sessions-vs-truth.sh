#!/usr/bin/env bash
# `imucal calibrate --sim` on several seeds, exactly as a user runs it (default speed), and the
# gyroscope's written A against the simulated board's truth: the worst scale error and the
# worst misalignment angle of E = A_fit·(Qᵀ·A_true)⁻¹ − I, where Q is the orthogonal factor of
# the accelerometer's true matrix (the frame the norm fit leaves the accelerometer in, which the
# gyroscope is aligned to), with the session's own 1σ and time. Sets up its own Python
# environment (numpy from PyPI) in target/sim-sessions-vs-truth.
# Usage: scripts/sim-sessions-vs-truth.sh [SEEDS] [FIRST_SEED]
set -euo pipefail
cd "$(dirname "$0")/.."
seeds=${1:-10}
first=${2:-1}
target=${CARGO_TARGET_DIR:-target}
mkdir -p "$target/sim-sessions-vs-truth"
target="$(cd "$target" && pwd)"
work="$target/sim-sessions-vs-truth"
if [ ! -x "$work/venv/bin/python" ]; then
    python3 -m venv "$work/venv"
    "$work/venv/bin/pip" install --quiet numpy
fi
cargo build --quiet --release -p imucal --bin imucal
imucal="$target/release/imucal"
runs="$work/runs"
rm -rf "$runs" && mkdir -p "$runs"
for seed in $(seq "$first" $((first + seeds - 1))); do
    mkdir -p "$runs/$seed"
    (cd "$runs/$seed" && "$imucal" calibrate --sim --yes --json --no-history --sim-seed "$seed" \
        > result.json 2> log.txt) || echo "seed $seed: the session failed (see $runs/$seed/log.txt)"
done
"$work/venv/bin/python" - "$runs" <<'PY'
import glob, json, os, sys
import numpy as np

print("seed | session s | moves | gyro scale err % (1σ) | misalign err ° (1σ)")
for run in sorted(glob.glob(os.path.join(sys.argv[1], "*")), key=lambda d: int(os.path.basename(d))):
    sessions = glob.glob(os.path.join(run, "imucal-session-*"))
    try:
        truth = json.load(open(os.path.join(sessions[0], "truth.json")))
        params = json.load(open(os.path.join(sessions[0], "params.json")))
        result = json.load(open(os.path.join(run, "result.json")))
    except (IndexError, OSError, ValueError) as error:
        print(f"{os.path.basename(run)} | no result ({error})")
        continue
    q, r = np.linalg.qr(np.array(truth["imu"]["accel"]["a_true"]))
    q = q * np.sign(np.diag(r))
    expected = q.T @ np.array(truth["imu"]["gyro"]["a_true"])
    e = np.array(params["gyro"]["A"]) @ np.linalg.inv(expected) - np.eye(3)
    scale = np.abs(np.diag(e)).max() * 100
    angle = np.degrees(np.abs(e - np.diag(np.diag(e))).max())
    g = result.get("gyro_scale") or {}
    print(f"{os.path.basename(run)} | {result['session_seconds']:.1f} | "
          f"{g.get('moves_used', 0)}/{g.get('moves_recorded', 0)} | "
          f"{scale:.3f} ({max(g.get('scale_sigma_pct', [float('nan')])):.3f}) | "
          f"{angle:.3f} ({g.get('misalignment_sigma_deg', float('nan')):.3f})")
PY
