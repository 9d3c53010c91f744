#!/bin/sh
# Installs what the tests start for real and the machine may lack, from
# Debian's packages: PostgreSQL's server programs (initdb, pg_ctl), which the
# service's tests run a temporary cluster with.
set -eu
if ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then
    exit 0
fi
SUDO=""
if [ "$(id -u)" != 0 ]; then
    SUDO=sudo
fi
echo "install-test-deps: installing Debian's postgresql package" >&2
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends postgresql >/dev/null
