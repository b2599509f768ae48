#!/usr/bin/env bash
# Runs the calibration-history tests against a throw-away PostgreSQL server.
# Installs Debian's postgresql when missing, starts a private server as the `postgres` user
# (initdb refuses root) on its own port and Unix-socket directory, runs the history tests and
# the write-time bench with IMUCAL_TEST_PG_URL pointing at it (the batch test records a
# simulated batch there too), and always stops it.
# Usage: scripts/ci-postgres.sh [release|dev]   (the cargo profile of the tests, default release)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
profile=()
[[ "${1:-release}" == release ]] && profile=(--release)

pg_bin() { ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1; }
if [[ -z "$(pg_bin)" || ! -x "$(pg_bin)/initdb" ]]; then
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends postgresql
fi
bin="$(pg_bin)"
# Debian's package starts its own cluster on 5432; ours is separate and private.
port="${IMUCAL_PG_PORT:-54329}"
dir="$(mktemp -d /tmp/imucal-pg.XXXXXX)"
chmod 755 "$dir"
mkdir -p "$dir/data" "$dir/socket"
chown postgres:postgres "$dir/data" "$dir/socket"
as_postgres() { runuser -u postgres -- "$@"; }

stop() {
  as_postgres "$bin/pg_ctl" -D "$dir/data" -m fast -w stop >/dev/null 2>&1 || true
  rm -rf "$dir"
}
trap stop EXIT

as_postgres "$bin/initdb" -D "$dir/data" -U postgres -A trust --no-sync >"$dir/initdb.log"
as_postgres "$bin/pg_ctl" -D "$dir/data" -l "$dir/socket/server.log" -w -t 60 \
  -o "-p $port -k $dir/socket -c listen_addresses='' -c fsync=on" start

export IMUCAL_TEST_PG_URL="postgres://postgres@/postgres?host=$dir/socket&port=$port"
echo "PostgreSQL $("$bin/postgres" --version | awk '{print $3}') on $IMUCAL_TEST_PG_URL"

# `--workspace`: the feature set of the workspace's test build, which CI has just made.
cargo test "${profile[@]}" --workspace --test history --test history_fleet --test batch_sim
cargo bench --workspace --bench history_write
