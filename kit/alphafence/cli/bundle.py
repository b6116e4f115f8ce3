"""alphafence bundle: sign and verify fence files (Ed25519): who made the fences.

Not MAVLink 2 link signing (``alphafence signing``, ``--signing-key``), which decides who may
talk to the vehicle."""

from __future__ import annotations

from alphafence.cli.common import out_console


def register(sub):
    """Add the ``bundle`` verb (keygen, sign, verify) to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "bundle",
        help="sign or verify fence files (Ed25519: who made the fences)",
        description="Authenticate fence files with Ed25519 signatures: who made the fences. "
        "'bundle keygen' makes a key pair: the private key signs fence files ('bundle sign', "
        "'compile --sign-key'), its public key lets 'upload' and 'monitor' accept them "
        "(--trusted-key KEY.pub.pem). This is not MAVLink 2 link signing ('alphafence "
        "signing keygen', --signing-key): that key is a secret shared with the vehicle: "
        "who may talk to the vehicle.",
    )
    verbs = p.add_subparsers(dest="bundle_verb", required=True, metavar="ACTION")
    k = verbs.add_parser(
        "keygen",
        help="make an Ed25519 key pair to sign fence files (not the vehicle link's key)",
    )
    k.add_argument(
        "--private",
        required=True,
        metavar="KEY.pem",
        help="write the private key here (mode 0600; keep it secret: it signs fences)",
    )
    k.add_argument(
        "--public",
        required=True,
        metavar="KEY.pub.pem",
        help="write the public key here (give it to upload and monitor as --trusted-key)",
    )
    s = verbs.add_parser("sign", help="sign FENCES (writes FENCES.sig.json)")
    s.add_argument("fences")
    s.add_argument("--key", required=True, metavar="KEY.pem", help="Ed25519 private key")
    v = verbs.add_parser("verify", help="check FENCES against trusted public keys")
    v.add_argument("fences")
    v.add_argument(
        "--trusted-key",
        required=True,
        action="append",
        metavar="KEY.pub.pem",
        help="a public key from 'bundle keygen' whose signature is accepted (repeatable)",
    )
    p.set_defaults(func=run)


def run(args) -> int:
    """Make a key pair, sign fences, or verify them (exit 2 when they do not verify)."""
    from alphafence.fencing.bundle import generate_key, sign, verify

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
