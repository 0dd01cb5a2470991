#!/usr/bin/env bash
# The services the skills lab's tests need, from Debian's packages: PostgreSQL (the session store on a
# real server) and Chromium (the dashboard's browser tests, driven by Playwright). Installs what is
# missing, starts PostgreSQL on localhost and makes the test role and database; safe to run again.
# The tests find the server at $SOFTENV_TEST_POSTGRES, by default the URL below.
set -euo pipefail
as_root() { if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi; }
as_postgres() { if [ "$(id -u)" -eq 0 ]; then runuser -u postgres -- "$@"; else sudo -u postgres "$@"; fi; }

missing=()
command -v chromium > /dev/null || missing+=(chromium)
ls /usr/lib/postgresql/*/bin/postgres > /dev/null 2>&1 || missing+=(postgresql)
if [ ${#missing[@]} -gt 0 ]; then
    as_root apt-get update -qq
    DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq --no-install-recommends "${missing[@]}" > /dev/null
fi

version=$(ls /usr/lib/postgresql | sort -V | tail -1)
pg_lsclusters -h | grep -q "^$version main" || as_root pg_createcluster "$version" main > /dev/null
pg_lsclusters -h | grep -q "^$version main .* online" || as_root pg_ctlcluster "$version" main start
for _ in $(seq 30); do as_postgres pg_isready -q && break; sleep 1; done
as_postgres psql -qtAc "SELECT 1 FROM pg_roles WHERE rolname = 'softenv'" | grep -q 1 \
    || as_postgres psql -qc "CREATE ROLE softenv LOGIN PASSWORD 'softenv' CREATEDB"
as_postgres psql -qtAc "SELECT 1 FROM pg_database WHERE datname = 'softenv_test'" | grep -q 1 \
    || as_postgres createdb -O softenv softenv_test
echo "test services: PostgreSQL $version on localhost:5432 (database softenv_test), $(chromium --version 2>/dev/null)"
