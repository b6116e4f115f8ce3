"""`make navio2-test`: the companion installed as the README tells a Navio2 user, on Debian
armhf under qemu-user, its unit tests, and a flight against x86 SITL (see run.sh)."""
