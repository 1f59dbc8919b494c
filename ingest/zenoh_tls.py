"""Zenoh over mutual TLS: the files a session needs, and a small CA that makes them.

Every millwatch process on a plant router network proves who it is with a certificate signed by
the site's own CA (mutual TLS, zenoh's ``transport/link/tls`` with ``enable_mtls``); the
router's access control (``deploy/zenoh/router.json5``, ``access_control``) matches the
certificate's common name (``cert_common_names``) to a role and lets each role use only its
keys. The common names are the roles:

=====================  =====================================================================
common name            role
=====================  =====================================================================
``router``             the zenoh router (its certificate also names the hosts it answers as)
``gateway.<site>.<mill>``  the gateway of one mill: publishes that mill's channels only
``worker``             a worker: subscribes to telemetry, answers the API's queries
``api``                ``millwatch api``: asks the workers, may acknowledge alarms
=====================  =====================================================================

:func:`tls_settings` is what :func:`millwatch.ingest.zenoh_session.build_config` inserts for a
:class:`TlsFiles`; :func:`make_ca` and :func:`make_certificate` make the files
(``millwatch zenoh-certs``; tests make their own the same way). Keys are ECDSA P-256, valid for
``days`` (default 825, the longest public CAs allow); private keys are written readable by
their owner only. ``cryptography`` is imported only by these two (every zenoh session imports
this module for :class:`TlsFiles`).
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric import ec

__all__ = [
    "ROLES",
    "TlsFiles",
    "gateway_name",
    "make_ca",
    "make_certificate",
    "tls_settings",
]

#: The roles a certificate's common name can name (``gateway`` is ``gateway.<site>.<mill>``).
ROLES = ("router", "gateway", "worker", "api")
DEFAULT_DAYS = 825


@dataclass(frozen=True, slots=True)
class TlsFiles:
    """PEM files of one zenoh session: the CA that signs every peer (``ca``), this process's
    certificate and its private key."""

    ca: Path
    certificate: Path
    private_key: Path


def tls_settings(files: TlsFiles) -> dict[str, Any]:
    """The ``transport/link/tls`` section for ``files``: the same certificate for the links this
    session opens and those it accepts, peers' certificates checked against ``ca`` both ways
    (mutual TLS), the router's host name checked on connect."""
    return {
        "root_ca_certificate": str(files.ca),
        "listen_certificate": str(files.certificate),
        "listen_private_key": str(files.private_key),
        "connect_certificate": str(files.certificate),
        "connect_private_key": str(files.private_key),
        "enable_mtls": True,
        "verify_name_on_connect": True,
    }


def gateway_name(site: str, mill: str) -> str:
    """The common name of a mill's gateway certificate: ``gateway.<site>.<mill>``."""
    return f"gateway.{site}.{mill}"


def _name(common_name: str) -> x509.Name:
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "millwatch"),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


def _write_key(path: Path, key: ec.EllipticCurvePrivateKey) -> None:
    from cryptography.hazmat.primitives import serialization

    pem = key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(pem)


def _write_cert(path: Path, cert: x509.Certificate) -> None:
    from cryptography.hazmat.primitives import serialization

    path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def _validity(builder: x509.CertificateBuilder, days: int) -> x509.CertificateBuilder:
    now = dt.datetime.now(dt.UTC)
    return builder.not_valid_before(now - dt.timedelta(minutes=5)).not_valid_after(
        now + dt.timedelta(days=days)
    )


def make_ca(directory: Path, *, days: int = 3650) -> tuple[Path, Path]:
    """A new CA in ``directory`` (``ca.pem``, ``ca-key.pem``; the key never leaves this
    host). Returns the two paths."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec

    directory.mkdir(parents=True, exist_ok=True)
    key = ec.generate_private_key(ec.SECP256R1())
    name = _name("millwatch CA")
    builder = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(False, False, False, False, False, True, True, False, False),
            critical=True,
        )
    )
    cert = _validity(builder, days).sign(key, hashes.SHA256())
    ca, ca_key = directory / "ca.pem", directory / "ca-key.pem"
    _write_key(ca_key, key)
    _write_cert(ca, cert)
    return ca, ca_key


def _alt_names(hosts: tuple[str, ...]) -> list[x509.GeneralName]:
    from cryptography import x509

    out: list[x509.GeneralName] = []
    for host in hosts:
        try:
            out.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            out.append(x509.DNSName(host))
    return out


def make_certificate(
    directory: Path,
    common_name: str,
    *,
    hosts: tuple[str, ...] = (),
    days: int = DEFAULT_DAYS,
) -> TlsFiles:
    """A certificate for ``common_name`` signed by the CA in ``directory`` (:func:`make_ca`),
    written as ``<common_name>.pem`` and ``<common_name>-key.pem``. ``hosts``: the DNS names
    or IP addresses a listening process (the router) is reached at, checked by connecting
    peers. Usable as client and server certificate (zenoh peers both connect and listen)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID

    ca_cert = x509.load_pem_x509_certificate((directory / "ca.pem").read_bytes())
    loaded = serialization.load_pem_private_key((directory / "ca-key.pem").read_bytes(), None)
    if not isinstance(loaded, ec.EllipticCurvePrivateKey):
        raise ValueError(f"{directory / 'ca-key.pem'}: not an EC key made by make_ca")
    key = ec.generate_private_key(ec.SECP256R1())
    builder = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
    )
    alt = _alt_names(hosts or (common_name,))
    builder = builder.add_extension(x509.SubjectAlternativeName(alt), critical=False)
    cert = _validity(builder, days).sign(loaded, hashes.SHA256())
    files = TlsFiles(
        ca=directory / "ca.pem",
        certificate=directory / f"{common_name}.pem",
        private_key=directory / f"{common_name}-key.pem",
    )
    _write_key(files.private_key, key)
    _write_cert(files.certificate, cert)
    return files
