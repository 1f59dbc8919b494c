"""The trust list of client application certificates: an unknown certificate is refused (and
saved for the administrator), a trusted one — or one a trusted CA issued — accepted, an expired
one refused even if trusted; the directory is read again when it changes."""

from __future__ import annotations

import asyncio
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.crypto import uacrypto
from asyncua.crypto.cert_gen import (
    generate_app_certificate_signing_request,
    generate_private_key,
    generate_self_signed_app_certificate,
    sign_certificate_request,
)
from cryptography import x509
from cryptography.hazmat.primitives import hashes
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from millwatch.opcua.trust import ClientTrust

APP = ua.ApplicationDescription(ApplicationUri="urn:millwatch:test:scada")


async def _certificate(directory: Path, name: str, days: int = 30) -> x509.Certificate:
    """A self-signed client application certificate valid from now for ``days`` (0: already
    expired when checked)."""
    key = generate_private_key()
    uri = x509.UniformResourceIdentifier(APP.ApplicationUri)
    return generate_self_signed_app_certificate(
        key, f"test {name}", {}, [uri, x509.DNSName("localhost")],
        [ExtendedKeyUsageOID.CLIENT_AUTH], days=days,
    )  # fmt: skip


def _refusal(trust: ClientTrust, cert: x509.Certificate) -> int | None:
    try:
        asyncio.run(trust(cert, APP))
    except ServiceError as exc:
        return int(exc.code)
    return None


def test_unknown_refused_and_saved_trusted_accepted(tmp_path: Path) -> None:
    trust = ClientTrust(tmp_path / "pki" / "trusted", tmp_path / "pki" / "rejected")
    cert = asyncio.run(_certificate(tmp_path, "scada"))
    assert _refusal(trust, cert) == ua.StatusCodes.BadCertificateUntrusted
    saved = list((tmp_path / "pki" / "rejected").iterdir())
    assert [p.read_bytes() for p in saved] == [uacrypto.der_from_x509(cert)]
    saved[0].rename(tmp_path / "pki" / "trusted" / saved[0].name)  # the administrator trusts it
    assert _refusal(trust, cert) is None
    other = asyncio.run(_certificate(tmp_path, "stranger"))
    assert _refusal(trust, other) == ua.StatusCodes.BadCertificateUntrusted


@pytest.mark.parametrize("junk", [b"", b"not a certificate"])
def test_a_file_that_is_no_certificate_is_ignored(tmp_path: Path, junk: bytes) -> None:
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    (trusted / "broken.der").write_bytes(junk)
    cert = asyncio.run(_certificate(tmp_path, "scada"))
    trust = ClientTrust(trusted, tmp_path / "rejected")
    assert _refusal(trust, cert) == ua.StatusCodes.BadCertificateUntrusted
    (trusted / "scada.der").write_bytes(uacrypto.der_from_x509(cert))
    assert _refusal(trust, cert) is None


def test_an_expired_certificate_is_refused_even_when_trusted(tmp_path: Path) -> None:
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    cert = asyncio.run(_certificate(tmp_path, "old", days=0))
    time.sleep(1.1)  # (X.509 times have whole seconds)
    (trusted / "old.der").write_bytes(uacrypto.der_from_x509(cert))
    trust = ClientTrust(trusted, tmp_path / "rejected")
    assert _refusal(trust, cert) == ua.StatusCodes.BadCertificateTimeInvalid


def _ca() -> tuple[x509.Certificate, Any]:
    """A plant CA: self-signed, ``CA:TRUE``, may sign certificates."""
    key = generate_private_key()
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "plant CA")])
    now = datetime.now(UTC)
    cert = (
        x509.CertificateBuilder().subject_name(name).issuer_name(name)
        .public_key(key.public_key()).serial_number(x509.random_serial_number())
        .not_valid_before(now - timedelta(minutes=1)).not_valid_after(now + timedelta(days=30))
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False,
                                     key_encipherment=False, data_encipherment=False,
                                     key_agreement=False, key_cert_sign=True, crl_sign=True,
                                     encipher_only=False, decipher_only=False), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                       critical=False)
        .sign(key, hashes.SHA256())
    )  # fmt: skip
    return cert, key


def test_a_certificate_issued_by_a_trusted_ca_is_accepted(tmp_path: Path) -> None:
    ca, ca_key = _ca()
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    (trusted / "plant-ca.der").write_bytes(uacrypto.der_from_x509(ca))
    key = generate_private_key()
    csr = generate_app_certificate_signing_request(
        key, "scada", {}, [x509.UniformResourceIdentifier(APP.ApplicationUri)],
        [ExtendedKeyUsageOID.CLIENT_AUTH],
    )  # fmt: skip
    issued = sign_certificate_request(csr, ca, ca_key, days=30)
    trust = ClientTrust(trusted, tmp_path / "rejected")
    assert _refusal(trust, issued) is None
    stranger = asyncio.run(_certificate(tmp_path, "stranger"))
    assert _refusal(trust, stranger) == ua.StatusCodes.BadCertificateUntrusted
