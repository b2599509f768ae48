#!/usr/bin/env bash
# Installs what building the imucal firmware for Cortex-M4F and running it in QEMU needs on Debian 12:
# Debian's rustc/cargo 1.96 with the library sources (for `-Z build-std=core`), ld.lld, qemu-system-arm,
# and binutils' `size`. Packages already present are left alone; `apt-get update` runs only when
# something is missing. Optional: `--with-defmt-print` also installs `defmt-print` with cargo to decode
# the firmware's logs.
# The layout and QEMU usage are described in firmware/boards/qemu-mps2-an386/README.md.
set -euo pipefail

packages=(rustc-web cargo-web rust-web-src lld qemu-system-arm binutils gcc)
with_defmt_print=0
for arg in "$@"; do
  case "$arg" in
    --with-defmt-print) with_defmt_print=1 ;;
    -h|--help)
      echo "usage: $0 [--with-defmt-print]"
      exit 0 ;;
    *)
      echo "error: unknown argument '$arg' (usage: $0 [--with-defmt-print])" >&2
      exit 2 ;;
  esac
done

missing=()
for pkg in "${packages[@]}"; do
  status="$(dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null || true)"
  if [[ "$status" != "install ok installed" ]]; then
    missing+=("$pkg")
  fi
done

sudo_cmd=()
if [[ "$(id -u)" -ne 0 ]]; then
  if command -v sudo >/dev/null 2>&1; then
    sudo_cmd=(sudo)
  elif [[ ${#missing[@]} -gt 0 ]]; then
    echo "error: packages ${missing[*]} are missing and installing them needs root; run this script as root or install sudo" >&2
    exit 1
  fi
fi

if [[ ${#missing[@]} -gt 0 ]]; then
  echo "installing: ${missing[*]}"
  "${sudo_cmd[@]}" apt-get update
  # Without --no-install-recommends qemu pulls in ~150 GUI/EFI packages that are never used.
  "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive \
    apt-get install -y --no-install-recommends "${missing[@]}"
else
  echo "all packages present: ${packages[*]}"
fi

# Check the pieces the build relies on; the rustup proxy `cargo` ignores build-std, so the board build
# always calls /usr/bin/cargo.
fail=0
for tool in /usr/bin/cargo /usr/bin/rustc ld.lld qemu-system-arm size gcc; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    echo "error: '$tool' not found after installation" >&2
    fail=1
  fi
done
if [[ ! -d /usr/lib/rustlib/src/rust/library/core ]]; then
  echo "error: core library sources missing at /usr/lib/rustlib/src/rust/library (package rust-web-src)" >&2
  fail=1
fi
[[ $fail -eq 0 ]] || exit 1

if [[ $with_defmt_print -eq 1 ]] && ! command -v defmt-print >/dev/null 2>&1; then
  cargo install defmt-print --locked
fi

echo "firmware toolchain ready: $(/usr/bin/rustc --version), $(qemu-system-arm --version | head -n1)"
