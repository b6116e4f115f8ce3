"""`make navio2-test`: the companion installed as the README tells a Navio2 user, on Debian
armhf under qemu-user, its unit tests, and a flight against x86 SITL (see run.sh)."""


def rootfs_args(prog: str, out: str, out_help: str, argv=None):
    """The ``--rootfs DIR [--out DIR]`` command line of a phase run against the installed
    userland (the flight, the bench); ``--out`` is created."""
    import argparse
    from pathlib import Path

    p = argparse.ArgumentParser(prog=prog)
    p.add_argument("--rootfs", required=True, type=Path, help="the armhf userland, installed")
    p.add_argument("--out", type=Path, default=Path(out), help=out_help)
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    return args
