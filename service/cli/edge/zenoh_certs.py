"""``millwatch zenoh-certs DIR``: a CA and one certificate per role for zenoh over mutual TLS.

Makes, in ``DIR`` (e.g. ``/etc/millwatch/tls``), what ``deploy/zenoh/router.json5`` and the
``[zenoh.tls]`` of the workers and the API read (:mod:`millwatch.ingest.zenoh_tls`):

* ``ca.pem``, ``ca-key.pem`` — the site's CA, made once (an existing CA is kept: certificates
  signed by it stay valid). Keep ``ca-key.pem`` off the other hosts.
* ``router.pem`` — the router, named by ``--router-host`` (the names and addresses its clients
  connect to; ``localhost`` and ``127.0.0.1`` always);
* ``worker.pem``, ``api.pem`` — the roles the router's access control knows by these names;
* ``gateway.<site>.<mill>.pem`` — one per mill of ``--mills`` (mill files or a directory), and per
  ``--gateway SITE/MILL``: a gateway publishes only that mill's channels.

Each ``<name>.pem`` has its key ``<name>-key.pem`` (readable by its owner only). An existing
certificate is kept unless ``--renew``. Copy to each host the CA and its own certificate and
key only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from millwatch.ingest.mill_files import load_mill_config, load_mill_configs
from millwatch.ingest.zenoh_tls import DEFAULT_DAYS, gateway_name, make_ca, make_certificate

__all__ = ["add_parser", "role_names"]

_LOCAL_HOSTS = ("localhost", "127.0.0.1")


def _gateway(text: str) -> str:
    site, sep, mill = text.partition("/")
    if not (sep and site and mill) or "/" in mill:
        raise argparse.ArgumentTypeError(f"expected SITE/MILL, e.g. rustenburg/sag-5200-lrs, "
                                         f"got {text!r}")  # fmt: skip
    return gateway_name(site, mill)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "zenoh-certs",
        help="make a CA and the certificates of the router, workers, API and gateways (mTLS)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "example:\n"
            "  millwatch zenoh-certs /etc/millwatch/tls \\\n"
            "      --router-host zenoh-router.plant.example --mills deploy/mills"
        ),
    )  # fmt: skip
    p.add_argument("directory", type=Path, help="where the files go (made if missing)")
    p.add_argument("--router-host", action="append", default=[], metavar="HOST",
                   help="a name or address clients reach the router at (repeatable)")  # fmt: skip
    p.add_argument("--mills", action="append", default=[], type=Path, metavar="PATH",
                   help="mill files or a directory of them: a gateway certificate per "
                   "mill")  # fmt: skip
    p.add_argument("--gateway", action="append", default=[], type=_gateway, metavar="SITE/MILL",
                   help="one more gateway certificate (repeatable)")  # fmt: skip
    p.add_argument("--days", type=int, default=DEFAULT_DAYS, help="validity of the certificates")
    p.add_argument("--renew", action="store_true", help="remake certificates that exist")
    p.set_defaults(handler=_main)


def role_names(mills: list[Path], gateways: list[str]) -> list[str]:
    """The certificate names to make: worker, api, then a gateway per mill and per ``gateways``."""
    names = ["worker", "api"]
    for path in mills:
        configs = load_mill_configs(path) if path.is_dir() else {"": load_mill_config(path)}
        names += [gateway_name(c.site, c.id) for c in configs.values()]
    return list(dict.fromkeys(names + gateways))


def _main(args: argparse.Namespace) -> int:
    d: Path = args.directory
    if (d / "ca.pem").exists() and (d / "ca-key.pem").exists():
        sys.stderr.write(f"keeping the CA in {d / 'ca.pem'}\n")
    else:
        make_ca(d)
        sys.stderr.write(f"made a new CA: {d / 'ca.pem'} (keep {d / 'ca-key.pem'} here only)\n")
    hosts = tuple(dict.fromkeys([*_LOCAL_HOSTS, *args.router_host]))
    wanted = [("router", hosts)] + [(n, ()) for n in role_names(args.mills, args.gateway)]
    for name, names in wanted:
        if (d / f"{name}.pem").exists() and not args.renew:
            sys.stderr.write(f"kept {d / f'{name}.pem'} (--renew remakes it)\n")
            continue
        files = make_certificate(d, name, hosts=names, days=args.days)
        sys.stdout.write(f"{files.certificate}\n")
    return 0
