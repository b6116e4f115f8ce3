"""alphafence bundle: sign and verify fence databases (Ed25519)."""

from __future__ import annotations

from alphafence.cli.common import out_console


def register(sub):
    """Add the ``bundle`` verb (keygen, sign, verify) to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "bundle",
        help="sign or verify a fence database",
        description="Authenticate fence databases with Ed25519 signatures.",
    )
    verbs = p.add_subparsers(dest="bundle_verb", required=True, metavar="ACTION")
    k = verbs.add_parser("keygen", help="make a signing key pair")
    k.add_argument("--private", required=True, metavar="KEY.pem")
    k.add_argument("--public", required=True, metavar="KEY.pub.pem")
    s = verbs.add_parser("sign", help="sign FENCES (writes FENCES.sig.json)")
    s.add_argument("fences")
    s.add_argument("--key", required=True, metavar="KEY.pem", help="Ed25519 private key")
    v = verbs.add_parser("verify", help="check FENCES against trusted public keys")
    v.add_argument("fences")
    v.add_argument("--trusted-key", required=True, action="append", metavar="KEY.pub.pem")
    p.set_defaults(func=run)


def run(args) -> int:
    """Make a key pair, sign fences, or verify them (exit 2 when they do not verify)."""
    from alphafence.build.bundle import generate_key, sign, verify

    if args.bundle_verb == "keygen":
        generate_key(args.private, args.public)
        out_console.print(f"wrote {args.private} (keep it secret) and {args.public}")
    elif args.bundle_verb == "sign":
        out_console.print(f"wrote {sign(args.fences, args.key)}")
    else:
        meta = verify(args.fences, args.trusted_key)
        out_console.print(
            f"{args.fences}: authentic (signed {meta.get('signed_at')} by a trusted key, {meta.get('tool')})"
        )
    return 0
