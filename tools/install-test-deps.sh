#!/bin/sh
# Installs what the tests start for real and the machine may lack:
# - PostgreSQL's server programs (initdb, pg_ctl), from Debian's packages,
#   which the service's tests run a temporary cluster with;
# - Debian's chromium, the headless browser the web page's tests drive
#   (server/tests/web.rs, over tools/chromium-cdp.py);
# - an S3-compatible server (moto's, from PyPI) in a virtual environment of
#   the project's (target/test-venv), which the artifact store's S3 test
#   runs on a loopback port.
set -eu
cd "$(dirname "$0")/.."
SUDO=""
if [ "$(id -u)" != 0 ]; then
    SUDO=sudo
fi
if ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then
    echo "install-test-deps: installing Debian's postgresql package" >&2
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends postgresql >/dev/null
fi
if ! command -v chromium >/dev/null 2>&1; then
    echo "install-test-deps: installing Debian's chromium package" >&2
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends chromium >/dev/null \
        || echo "install-test-deps: chromium could not be installed: the web page's browser test \
will fail (set IMPOSTOR_SKIP_BROWSER_TESTS=1 to skip it)" >&2
fi
VENV=target/test-venv
if ! "$VENV/bin/python" -c 'import moto.server' >/dev/null 2>&1; then
    echo "install-test-deps: installing moto's S3 server in $VENV" >&2
    python3 -m venv --clear "$VENV"
    "$VENV/bin/pip" install -q --disable-pip-version-check 'moto[server]==5.2.1'
fi
