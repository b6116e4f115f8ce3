#!/usr/bin/env bash
# `make navio2-test`: the companion on a Navio2's OS, Debian armhf (32-bit Raspberry Pi OS), run
# under qemu-user on this x86 machine. Needs root (debootstrap, chroot, mounts). Phases, each timed:
#   userland  debootstrap a Debian SUITE armhf userland ONCE, cached outside the repository in
#             ${ALPHAFENCE_CACHE:-~/.cache/alphafence}/navio2/SUITE-armhf (complete when its
#             stamp file is there; rebuilt when it is missing)
#   install   a fresh overlay over that userland (the cache stays pristine), the kit's source at
#             /root/alphafence, then the README's `<!-- navio2-install: SUITE -->` blocks, run as
#             they are written, as root, with a clean environment (env -i): the host's pip and CA
#             settings stay out (only the machine's extra CA certificates, if it has any, go into
#             the userland's system trust store, as a Pi behind such a proxy would need)
#   tests     the unit tests of the companion's code under qemu (SELECTION below)
#   flight    x86 ArduPilot SITL; the armhf monitor started as the systemd unit starts it
#             (docker/alphafence-monitor.service: its user, ExecStart and environment, plus
#             enforce and the SITL port) on SITL's second MAVLink link over loopback; a flight
#             from the host at a keep-out fence (tests/navio2/flight.py)
#   bench     the monitor's CPU per position on x86 SITL's stream at 10 and 50 Hz, measured by
#             bench/monitor_probe.py on x86 and in the userland under qemu-user (emulated),
#             each beside the floor (tests/navio2/bench.py); results in $LOGS/bench/
#   docker    (trixie) docker/Dockerfile.armv7's steps in another fresh overlay: no Docker
#             engine here, so its RUN/COPY/ENV run as a script (tests/navio2/dockerfile.py)
# Environment: NAVIO2_SUITE (trixie | bookworm; default trixie), NAVIO2_PHASES (default
# "install tests flight bench docker"), NAVIO2_TESTS (pytest arguments instead of SELECTION),
# ALPHAFENCE_FUZZ_EXAMPLES (default 20 here), NAVIO2_KEEP=1 (keep this run's overlay: a later run
# without the install phase reuses it, with the checkout's kit put into it, no dependency changed).
# Logs: $CACHE/navio2/logs-SUITE/.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/../.." && pwd)
SUITE=${NAVIO2_SUITE:-trixie}
PHASES=${NAVIO2_PHASES:-install tests flight bench docker}
CACHE=${ALPHAFENCE_CACHE:-$HOME/.cache/alphafence}/navio2
BASE=$CACHE/$SUITE-armhf
STAMP=$BASE/.alphafence-userland
RUN=$CACHE/$SUITE-run
ROOTFS=$RUN/root
LOGS=$CACHE/logs-$SUITE
SHARED=$(cd "$ROOT/.." && pwd)/shared
MIRROR=${NAVIO2_MIRROR:-http://deb.debian.org/debian}
HOSTPY=$ROOT/.venv/bin/python
FUZZ=${ALPHAFENCE_FUZZ_EXAMPLES:-20}

# The companion's code and what it stands on, on the installed package (about 4.5 minutes
# under qemu): the monitor (engine, state, prediction, onboard layer and its decoding, event
# log, observers, replay, traffic, time windows, rolling fence), the vehicle link against
# tests/fake_vehicle.py (upload faults, hostile vehicle input: the MAVSDK cases skip, the
# pymavlink ones run), signing and signed bundles, the navio2 profile and BRD_SD_FENCE, MAVLink
# ids, geo (outward simplification), the format readers (OSM on Malta when ../shared is there),
# every module's doctests, the entrypoint and the README's install steps, the per-position check
# (grid, track ahead) and the link's filter against a full parse. Left out: the
# source-tree checks (test_layout reads the tree, not the install), the CLI, builds, routes and
# the comparisons, which need no armhf run to be trusted, and SITL (x86 only: the flight).
SELECTION=(
    tests/test_monitor_engine.py tests/test_monitor_core.py tests/test_monitor_onboard.py
    tests/test_monitor_onboard_decode.py tests/test_monitor_onboard_runner.py
    tests/test_monitor_eventlog.py tests/test_monitor_observer.py tests/test_monitor_replay.py
    tests/test_monitor_traffic.py tests/test_monitor_timewindows.py tests/test_monitor_rolling.py
    tests/test_upload_faults.py tests/test_fuzz_vehicle_input.py tests/test_signing.py
    tests/test_bundle.py tests/test_navio2.py tests/test_mavlink_ids.py tests/test_outward.py
    tests/test_readers.py tests/test_doctests.py tests/test_docker_entrypoint.py
    tests/test_navio2_install.py tests/test_monitor_fastcheck.py tests/test_mavlink_filter.py
)

USERLAND_PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
declare -A SECONDS_OF=()
FAILED=""

say() { printf '\n== navio2-test [%s]: %s\n' "$SUITE" "$*"; }
die() { echo "navio2-test: $*" >&2; exit 1; }

# a command in the userland, as root, with nothing of the host's environment but these
in_userland() {
    env -i PATH=$USERLAND_PATH HOME=/root LANG=C.UTF-8 TERM=dumb \
        DEBIAN_FRONTEND=noninteractive "$@"
}

mounts_under() {  # the mount points under $1, deepest first
    awk -v dir="$1/" 'index($2, dir) == 1 { print $2 }' /proc/mounts | sort -r
}

cleanup() {  # unmount this suite's run userlands; remove them unless NAVIO2_KEEP=1
    local run m
    for run in "$CACHE/$SUITE-run" "$CACHE/$SUITE-docker"; do
        for m in $(mounts_under "$run"); do
            umount "$m" 2>/dev/null || umount -l "$m" 2>/dev/null || true
        done
        [ "${NAVIO2_KEEP:-0}" != 1 ] && [ -d "$run" ] || continue
        if [ -n "$(mounts_under "$run")" ]; then  # never delete through a bind of /dev or /sys
            echo "navio2-test: $run still has mounts; not removed" >&2
        else
            rm -rf "$run"
        fi
    done
}
trap cleanup EXIT

timed() {  # timed <phase> <function>: runs it in a subshell with errexit, times it
    local phase=$1 t0=$SECONDS status
    shift
    set +e
    (set -e; "$@")  # not in an || list, where bash would ignore errexit inside
    status=$?
    set -e
    SECONDS_OF[$phase]=$((SECONDS - t0))
    if [ $status -ne 0 ]; then
        FAILED="$FAILED $phase"
        echo "navio2-test: phase $phase failed (exit $status) after ${SECONDS_OF[$phase]} s" >&2
    fi
    return $status
}

# -- host: debootstrap, qemu-user-static, binfmt_misc ------------------------------------------
host_setup() {
    [ "$(id -u)" = 0 ] || die "run as root (debootstrap, chroot and mounts need it)"
    [ -x "$HOSTPY" ] || die "no $HOSTPY: run make install first"
    local missing=()
    command -v debootstrap >/dev/null || missing+=(debootstrap)
    [ -e /usr/bin/qemu-arm-static ] || missing+=(qemu-user-static)
    command -v update-binfmts >/dev/null || missing+=(binfmt-support)
    if [ ${#missing[@]} -gt 0 ]; then
        say "installing ${missing[*]} from Debian"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
    fi
    if [ ! -e /proc/sys/fs/binfmt_misc/status ]; then
        mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc
    fi
    [ -e /proc/sys/fs/binfmt_misc/qemu-arm ] || update-binfmts --enable qemu-arm
    grep -q '^enabled' /proc/sys/fs/binfmt_misc/qemu-arm 2>/dev/null ||
        die "qemu-arm is not registered in binfmt_misc (update-binfmts --enable qemu-arm)"
    # F: the interpreter is opened at registration, so it works inside a chroot
    grep -q '^flags:.*F' /proc/sys/fs/binfmt_misc/qemu-arm ||
        die "qemu-arm's binfmt entry lacks the F flag; reinstall qemu-user-static"
}

# -- userland: Debian armhf, built once -------------------------------------------------------
userland() {
    if [ -f "$STAMP" ]; then
        echo "reusing $BASE ($(head -1 "$STAMP"))"
        return 0
    fi
    say "debootstrap $SUITE armhf into $BASE (once; 2-3 minutes)"
    rm -rf "$BASE.partial"
    mkdir -p "$CACHE"
    # sudo and ca-certificates come with Raspberry Pi OS; the rest is the README's to install
    debootstrap --arch=armhf --variant=minbase --include=ca-certificates,sudo \
        "$SUITE" "$BASE.partial" "$MIRROR"
    rm -rf "$BASE"
    mv "$BASE.partial" "$BASE"
    printf 'debian %s armhf, debootstrap %s, %s\n' "$SUITE" "$MIRROR" "$(date -u +%FT%TZ)" \
        >"$STAMP"
}

# -- install: the README's blocks in a fresh overlay ------------------------------------------
mount_userland() {  # mount_userland fresh|reuse (reuse: a kept run's overlay, NAVIO2_KEEP=1)
    local m
    if [ "$1" = fresh ]; then  # this run's folder from scratch
        for m in $(mounts_under "$RUN"); do umount "$m" 2>/dev/null || umount -l "$m"; done
        [ -z "$(mounts_under "$RUN")" ] || die "$RUN still has mounts"
        rm -rf "$RUN"
    fi
    mkdir -p "$RUN/upper" "$RUN/work" "$ROOTFS" "$CACHE/apt-archives-$SUITE" "$CACHE/pip-cache"
    if ! mount -t overlay overlay \
        -o "lowerdir=$BASE,upperdir=$RUN/upper,workdir=$RUN/work" "$ROOTFS" 2>/dev/null; then
        echo "(no overlayfs here: copying the userland)"
        if [ "$1" = fresh ]; then
            rmdir "$ROOTFS"
            cp -a "$BASE" "$ROOTFS"
        fi
    fi
    mount -t proc proc "$ROOTFS/proc"
    mount --rbind /sys "$ROOTFS/sys"
    mount --make-rslave "$ROOTFS/sys"
    mount --rbind /dev "$ROOTFS/dev"
    mount --make-rslave "$ROOTFS/dev"
    # downloads kept between runs: Debian's .debs and pip's wheel cache
    mount --bind "$CACHE/apt-archives-$SUITE" "$ROOTFS/var/cache/apt/archives"
    mkdir -p "$ROOTFS/root/.cache/pip"
    mount --bind "$CACHE/pip-cache" "$ROOTFS/root/.cache/pip"
    # the OSM extracts, read-only, where the tests look for them (beside the checkout)
    if [ -d "$SHARED" ]; then
        mkdir -p "$ROOTFS/root/shared"
        mount --bind -o ro "$SHARED" "$ROOTFS/root/shared"
    fi
    cp -L /etc/resolv.conf "$ROOTFS/etc/resolv.conf"
    cp -L /etc/hosts "$ROOTFS/etc/hosts"
    local cas=(/usr/local/share/ca-certificates/*.crt)
    if [ -e "${cas[0]}" ]; then
        cp "${cas[@]}" "$ROOTFS/usr/local/share/ca-certificates/"
        in_userland chroot "$ROOTFS" update-ca-certificates >/dev/null 2>&1
    fi
}

copy_source() {  # copy_source DEST: the kit as a user's clone (tracked and new files)
    local dest=$1
    rm -rf "$dest"
    mkdir -p "$dest"
    (cd "$ROOT" && git ls-files -z --cached --others --exclude-standard |
        xargs -0 -I{} sh -c 'test -e "{}" && printf "%s\0" "{}"' |
        tar --null -T - -cf -) | tar -xf - -C "$dest"
}

install_kit() {
    mount_userland fresh
    copy_source "$ROOTFS/root/alphafence"
    "$HOSTPY" -m tests.navio2.readme blocks "$SUITE" >"$ROOTFS/root/navio2-install.sh"
    say "the README's install steps for $SUITE, in the armhf userland:"
    sed 's/^/    /' "$ROOTFS/root/navio2-install.sh"
    # each step echoed with the seconds since the start (bash takes no PS4 from root's environment)
    in_userland chroot "$ROOTFS" bash -c \
        'PS4="+ [\${SECONDS} s] "; set -euxo pipefail; . /root/navio2-install.sh' </dev/null
    in_userland chroot "$ROOTFS" sh -c '
        uname -m; python3 --version
        /opt/alphafence/bin/alphafence --version
        /opt/alphafence/bin/python -c "import alphafence.vehicle.link, pymavlink; print(\"pymavlink\", pymavlink.__version__ if hasattr(pymavlink, \"__version__\") else \"\")"
        /opt/alphafence/bin/pip list --format=freeze 2>/dev/null | grep -i -E "^(alphafence|pymavlink|fastcrc|numpy|shapely|pyproj|scipy|osmium|matplotlib|cryptography|rich|lxml)=" || true'
}

# -- tests under qemu -------------------------------------------------------------------------
run_tests() {
    # the test tools are not part of the user's install: Debian's, from apt
    in_userland chroot "$ROOTFS" apt-get install -y -qq \
        python3-pytest python3-hypothesis python3-pytest-asyncio >/dev/null
    local args=("${SELECTION[@]}")
    [ -z "${NAVIO2_TESTS:-}" ] || read -r -a args <<<"$NAVIO2_TESTS"
    say "unit tests under qemu: ${#args[@]} arguments, ALPHAFENCE_FUZZ_EXAMPLES=$FUZZ"
    # the CI hypothesis profile (no deadline, fixed seed; tests/ci_env.py) without CI's skip
    # rule: qemu is 10-20x slower, and the companion's install has no browser or MAVSDK
    in_userland ALPHAFENCE_HYPOTHESIS_PROFILE=ci ALPHAFENCE_FUZZ_EXAMPLES="$FUZZ" chroot "$ROOTFS" sh -c \
        'cd /root/alphafence && exec /opt/alphafence/bin/python -m pytest -q -p no:cacheprovider -m "not sitl" "$@"' \
        pytest "${args[@]}" 2>&1 | tee "$LOGS/tests.log"
    return "${PIPESTATUS[0]}"
}

# -- the flight: x86 SITL, the armhf monitor, a scripted approach -------------------------------
flight() {
    say "flight: x86 SITL, armhf monitor as the systemd unit runs it, GUIDED at a keep-out fence"
    (cd "$ROOT" && "$HOSTPY" -m tests.navio2.flight --rootfs "$ROOTFS" --out "$LOGS/flight") 2>&1 |
        tee "$LOGS/flight.log"
    return "${PIPESTATUS[0]}"
}

# -- the monitor's CPU on armhf (emulated) beside x86 --------------------------------------------
bench_phase() {
    say "bench: the monitor's CPU per position, x86 and armhf under qemu-user, on x86 SITL"
    (cd "$ROOT" && "$HOSTPY" -m tests.navio2.bench --rootfs "$ROOTFS" --out "$LOGS/bench") 2>&1 |
        tee "$LOGS/bench.log"
    return "${PIPESTATUS[0]}"
}

# -- docker/Dockerfile.armv7's steps in a fresh overlay ----------------------------------------
docker_steps() {
    [ "$SUITE" = trixie ] || { echo "(the armv7 image is trixie's: skipped on $SUITE)"; return 0; }
    cleanup
    RUN=$CACHE/$SUITE-docker
    ROOTFS=$RUN/root
    mount_userland fresh
    copy_source "$ROOTFS/context"
    "$HOSTPY" -m tests.navio2.dockerfile "$ROOT/docker/Dockerfile.armv7" debian:trixie-slim \
        >"$ROOTFS/root/dockerfile.sh"
    say "docker/Dockerfile.armv7's steps in a fresh armhf userland (no Docker engine here):"
    sed 's/^/    /' "$ROOTFS/root/dockerfile.sh"
    in_userland chroot "$ROOTFS" bash /root/dockerfile.sh 2>&1 | tee "$LOGS/docker.log"
    return "${PIPESTATUS[0]}"
}

summary() {
    local phase
    say "summary"
    for phase in userland install tests flight bench docker; do
        [ -n "${SECONDS_OF[$phase]:-}" ] || continue
        printf '  %-9s %5d s  %s\n' "$phase" "${SECONDS_OF[$phase]}" \
            "$([[ " $FAILED " == *" $phase "* ]] && echo FAILED || echo ok)"
    done
    if [ -n "${SECONDS_OF[tests]:-}" ] && [ -f "$LOGS/tests.log" ]; then
        printf '  tests:    %s\n' "$(grep -E '(passed|failed|error)' "$LOGS/tests.log" | tail -1)"
    fi
    if [ -n "${SECONDS_OF[flight]:-}" ] && [ -f "$LOGS/flight.log" ]; then
        printf '  flight:   %s\n' "$(grep '^navio2 flight:' "$LOGS/flight.log" | tail -1)"
    fi
    if [ -n "${SECONDS_OF[bench]:-}" ] && [ -f "$LOGS/bench.log" ]; then
        printf '  bench:    %s\n' "$(grep '^navio2 bench:' "$LOGS/bench.log" | tail -1)"
    fi
    [ -z "$FAILED" ] || { echo "navio2-test: FAILED:$FAILED"; return 1; }
    echo "navio2-test: all phases passed"
}

main() {
    host_setup
    rm -rf "$LOGS"
    mkdir -p "$LOGS"
    timed userland userland || { summary; exit 1; }
    if [[ " $PHASES " == *" install "* ]]; then
        timed install install_kit || { summary; exit 1; }
    else
        [ -d "$RUN/upper/opt/alphafence" ] || [ -d "$ROOTFS/opt/alphafence" ] ||
            die "no kept install at $RUN (run once with NAVIO2_KEEP=1)"
        NAVIO2_KEEP=1
        mount_userland reuse
        say "the checkout's kit into the kept install (its dependencies as they are)"
        copy_source "$ROOTFS/root/alphafence"
        in_userland chroot "$ROOTFS" /opt/alphafence/bin/pip install -q --no-deps \
            --force-reinstall /root/alphafence
    fi
    if [[ " $PHASES " == *" tests "* ]]; then timed tests run_tests || true; fi
    if [[ " $PHASES " == *" flight "* ]]; then timed flight flight || true; fi
    if [[ " $PHASES " == *" bench "* ]]; then timed bench bench_phase || true; fi
    if [[ " $PHASES " == *" docker "* ]]; then timed docker docker_steps || true; fi
    summary
}

main "$@"
