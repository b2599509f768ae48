#!/usr/bin/env bash
# Renders an imucal HTML report in headless Chromium and fails when the screenshot is blank or
# the page is broken. Usage: scripts/check-report-renders.sh REPORT.html [SHOT.png]
# Without a report argument it builds one from a shipped recording first.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

if ! command -v chromium >/dev/null 2>&1; then
  # Debian's browser; CI machines start without it.
  apt-get update -qq
  apt-get install -y --no-install-recommends chromium
fi

report="${1:-}"
if [[ -z "$report" ]]; then
  out="$(mktemp -d)"
  cargo run -q --release -p imucal -- report data/real/sf_mpu6050_hmc5883l_full_sphere.csv \
    --accel-unit g --gyro-unit dps --mag-unit gauss --location 46.05,14.51 -o "$out"
  report="$out/report.html"
fi
shot="${2:-$(mktemp -d)/report.png}"

# The page must be self-contained: no scripts, style sheets, fonts or images from elsewhere.
if grep -Eq '<script|<link|@import|url\(|src="?https?:' "$report"; then
  echo "error: $report refers to outside resources" >&2
  exit 1
fi

profile="$(mktemp -d)"
timeout 120 chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
  --disable-background-networking --disable-component-update --disable-sync \
  --user-data-dir="$profile" --screenshot="$shot" --window-size=1200,3000 \
  "file://$(realpath "$report")" 2>/dev/null || true
rm -rf "$profile"
if [[ ! -s "$shot" ]]; then
  echo "error: chromium wrote no screenshot of $report" >&2
  exit 1
fi
# Built with the workspace's test feature set (as `cargo test --workspace --release` builds the
# examples), so after the tests nothing is rebuilt; `-p imucal` alone would rebuild the library.
cargo build -q --release --workspace --examples
"${CARGO_TARGET_DIR:-target}/release/examples/png_stats" "$shot"
echo "report renders: $shot"
