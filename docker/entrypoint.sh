#!/bin/sh
# Entrypoint of the AlphaFence companion image: `alphafence monitor` configured by environment.
#   ALPHAFENCE_CONNECT        MAVSDK URL of the vehicle (required), e.g. udpin://0.0.0.0:14550
#   ALPHAFENCE_FENCES         fence GeoJSON (required)
#   ALPHAFENCE_TRUSTED_KEYS   colon-separated Ed25519 public keys the fences must be signed with
#   ALPHAFENCE_ALLOW_UNSIGNED 1 to use fences that are not signed by a trusted key
#   ALPHAFENCE_ENFORCE        1 to brake/RTL/land, not only alert
#   ALPHAFENCE_HORIZON        look-ahead seconds (default 15)
#   ALPHAFENCE_BREACH_ACTION  rtl | land | brake | none (default rtl)
#   ALPHAFENCE_IMMINENT_ACTION brake | reroute | rtl | land | none (default brake)
#   ALPHAFENCE_ONBOARD        watch | off | rolling: check the vehicle's own fence as a layer (default
#                             watch); rolling also keeps it equal to the fences within reach (copter profile)
#   ALPHAFENCE_SIGNING_KEY    MAVLink 2 signing key file (read by alphafence itself)
#   ALPHAFENCE_LOG            JSON-lines event log path
# Extra arguments are passed on to `alphafence monitor`.
set -eu

fail() { echo "alphafence-entrypoint: $*" >&2; exit 64; }

[ -n "${ALPHAFENCE_CONNECT:-}" ] || fail "set ALPHAFENCE_CONNECT (e.g. udpin://0.0.0.0:14550)"
[ -n "${ALPHAFENCE_FENCES:-}" ] || fail "set ALPHAFENCE_FENCES to the fence GeoJSON"
[ -r "$ALPHAFENCE_FENCES" ] || fail "cannot read ALPHAFENCE_FENCES=$ALPHAFENCE_FENCES"

set -- --connect "$ALPHAFENCE_CONNECT" --fences "$ALPHAFENCE_FENCES" "$@"
case "${ALPHAFENCE_ENFORCE:-0}" in
    1|true|yes) set -- "$@" --enforce ;;
    0|false|no|"") ;;
    *) fail "ALPHAFENCE_ENFORCE must be 1 or 0, not '$ALPHAFENCE_ENFORCE'" ;;
esac
case "${ALPHAFENCE_ALLOW_UNSIGNED:-0}" in
    1|true|yes) set -- "$@" --allow-unsigned ;;
    0|false|no|"") ;;
    *) fail "ALPHAFENCE_ALLOW_UNSIGNED must be 1 or 0, not '$ALPHAFENCE_ALLOW_UNSIGNED'" ;;
esac
[ -z "${ALPHAFENCE_HORIZON:-}" ] || set -- "$@" --horizon "$ALPHAFENCE_HORIZON"
[ -z "${ALPHAFENCE_BREACH_ACTION:-}" ] || set -- "$@" --breach-action "$ALPHAFENCE_BREACH_ACTION"
[ -z "${ALPHAFENCE_IMMINENT_ACTION:-}" ] || set -- "$@" --imminent-action "$ALPHAFENCE_IMMINENT_ACTION"
[ -z "${ALPHAFENCE_ONBOARD:-}" ] || set -- "$@" --onboard "$ALPHAFENCE_ONBOARD"
[ -z "${ALPHAFENCE_LOG:-}" ] || set -- "$@" --log "$ALPHAFENCE_LOG"
# ALPHAFENCE_TRUSTED_KEYS and ALPHAFENCE_SIGNING_KEY are read by alphafence itself
exec alphafence monitor "$@"
