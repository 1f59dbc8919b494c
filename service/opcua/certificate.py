"""The OPC UA server's application instance certificate: self-signed, made at first start.

Basic256Sha256 needs a certificate and private key. At first start they are generated (RSA
2048, one year, with the application URI and host name as subject alternative names) into the
certificate directory — ``[opcua] certificate_dir``, by default ``opcua/`` beside the store, the
service's state directory — and reused afterwards; an expired or mismatching certificate is
made again (:func:`asyncua.crypto.cert_gen.setup_self_signed_certificate`). The private key file
is readable by its owner only. A plant that has its own PKI replaces both files.
"""

from __future__ import annotations

import socket
from pathlib import Path

from asyncua.crypto.cert_gen import setup_self_signed_certificate
from cryptography.x509.oid import ExtendedKeyUsageOID

__all__ = ["APPLICATION_URI", "CERT_FILE", "KEY_FILE", "ensure_certificate"]

APPLICATION_URI = "urn:millwatch:opcua:server"
CERT_FILE = "server-cert.der"
KEY_FILE = "server-key.pem"


async def ensure_certificate(directory: Path) -> tuple[Path, Path]:
    """``(certificate, private key)`` paths in ``directory``, generated when missing/invalid."""
    directory.mkdir(parents=True, exist_ok=True)
    cert, key = directory / CERT_FILE, directory / KEY_FILE
    await setup_self_signed_certificate(
        key, cert, APPLICATION_URI, socket.gethostname(),
        [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
        {"commonName": "millwatch OPC UA server", "organizationName": "millwatch"},
    )  # fmt: skip
    key.chmod(0o600)
    return cert, key
