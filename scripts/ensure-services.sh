#!/usr/bin/env bash
# Make sure the system services the test suite needs are present and running:
#   - PostgreSQL on 127.0.0.1:5432 with a database "test" (trust auth for local tests)
#   - Debian's chromium + chromium-driver for the browser tests
# Idempotent: does nothing when everything is already there. Needs root for apt-get.
set -euo pipefail

SUDO=""
if [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1; then SUDO="sudo"; fi
apt_updated=0
apt_install() {
  if ! command -v apt-get >/dev/null 2>&1; then
    echo "ensure-services: apt-get not available; install $* by hand" >&2
    return 1
  fi
  if [ "$apt_updated" -eq 0 ]; then $SUDO apt-get update -qq; apt_updated=1; fi
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "$@" >/dev/null
}

# --- PostgreSQL -----------------------------------------------------------------
pg_up() { pg_isready -q -h 127.0.0.1 -p 5432 2>/dev/null; }
if ! command -v pg_isready >/dev/null 2>&1 || ! pg_up; then
  if ! command -v pg_ctlcluster >/dev/null 2>&1; then
    echo "ensure-services: installing PostgreSQL"
    apt_install postgresql postgresql-client
  fi
  ver=$(ls /etc/postgresql 2>/dev/null | sort -V | tail -n 1)
  if [ -z "$ver" ]; then
    echo "ensure-services: no PostgreSQL cluster found after install" >&2; exit 1
  fi
  conf=/etc/postgresql/$ver/main
  # trust auth on loopback for the test database (a local, throw-away test server)
  if ! grep -q "scengen-test" "$conf/pg_hba.conf"; then
    $SUDO sed -i '1i host all all 127.0.0.1/32 trust # scengen-test\nhost all all ::1/128 trust # scengen-test\nlocal all all trust # scengen-test' "$conf/pg_hba.conf"
  fi
  $SUDO pg_ctlcluster --skip-systemctl-redirect "$ver" main start 2>/dev/null \
    || $SUDO pg_ctlcluster --skip-systemctl-redirect "$ver" main restart
  for _ in $(seq 1 30); do pg_up && break; sleep 1; done
  pg_up || { echo "ensure-services: PostgreSQL did not come up on 127.0.0.1:5432" >&2; exit 1; }
fi
if ! psql -h 127.0.0.1 -U postgres -tAc "select 1 from pg_database where datname='test'" 2>/dev/null | grep -q 1; then
  psql -h 127.0.0.1 -U postgres -c "create database test" >/dev/null 2>&1 || true
fi

# --- Chromium for Playwright (Debian's build; Playwright's own download is not used) ----
if [ ! -x /usr/bin/chromium ]; then
  echo "ensure-services: installing chromium"
  apt_install chromium chromium-driver
fi
echo "ensure-services: postgres and chromium ready"
