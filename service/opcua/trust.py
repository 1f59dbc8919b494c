"""Which client applications may open a session: the trust list of client certificates.

A client that signs (Sign, SignAndEncrypt) presents its application instance certificate. It is
accepted only when it is valid now (not expired, not yet valid) and *trusted*: the certificate
itself, or the CA that issued it, is a file (DER or PEM) in the trust directory —
``[opcua] trusted_clients_dir``, by default ``trusted/`` in the certificate directory. Anything
else is refused with ``BadCertificateUntrusted`` (an unknown self-signed certificate above all:
before, any was accepted), and the refused certificate is written to ``rejected/`` beside the
trust directory (named by its SHA-1 thumbprint), so an administrator who recognises it moves it
into the trust directory. The directory is read again whenever its contents change (no restart
to trust a new client). Clients on the ``None`` policy present no certificate and are not
checked here (whether ``None`` is offered is ``[opcua] security``).
"""

from __future__ import annotations

import logging
from datetime import UTC, datetime
from pathlib import Path

from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.crypto import uacrypto
from asyncua.crypto.truststore import TrustStore
from cryptography import x509
from cryptography.hazmat.primitives import hashes

__all__ = ["ClientTrust"]

log = logging.getLogger(__name__)

_SUFFIXES = (".der", ".pem", ".crt", ".cer")


class ClientTrust:
    """asyncua certificate validator over a trust directory (module docstring)."""

    def __init__(self, trusted_dir: Path, rejected_dir: Path) -> None:
        self.trusted_dir = trusted_dir
        self.rejected_dir = rejected_dir
        self._seen: tuple[tuple[str, int], ...] | None = None
        self._trusted: set[bytes] = set()
        self._store: x509.verification.Store | None = None
        self._policy = TrustStore([], [])  # (its verification policy, for CA-issued ones)

    def _listing(self) -> tuple[tuple[str, int], ...]:
        files = (p for p in self.trusted_dir.iterdir() if p.suffix.lower() in _SUFFIXES)
        return tuple(sorted((p.name, p.stat().st_mtime_ns) for p in files))

    async def _reload(self) -> None:
        self.trusted_dir.mkdir(parents=True, exist_ok=True)
        listing = self._listing()
        if listing == self._seen:
            return
        certs = []
        for name, _ in listing:
            try:
                certs.append(await uacrypto.load_certificate(self.trusted_dir / name))
            except (ValueError, OSError) as exc:
                log.warning("OPC UA trust list: %s is no certificate (%s); ignored", name, exc)
        self._trusted = {uacrypto.der_from_x509(c) for c in certs}
        # a CA's certificate in the list trusts what it issued (asyncua's verification policy;
        # its store refuses to be empty)
        self._store = x509.verification.Store(certs) if certs else None
        self._seen = listing
        log.info("OPC UA trust list: %d client certificates in %s", len(certs),
                 self.trusted_dir)  # fmt: skip

    def _issued_by_trusted(self, cert: x509.Certificate) -> bool:
        if self._store is None:
            return False
        verifier = self._policy.policy_builder.store(self._store).build_client_verifier()
        try:
            verifier.verify(cert, [])
        except Exception:  # VerificationError, or a certificate the verifier cannot read
            return False
        return True

    async def __call__(self, cert: x509.Certificate, app: ua.ApplicationDescription) -> None:
        """Raise ``ServiceError`` (``BadCertificateTimeInvalid``/``Untrusted``) unless valid
        and trusted."""
        await self._reload()
        now = datetime.now(UTC)
        if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
            raise ServiceError(ua.StatusCodes.BadCertificateTimeInvalid)
        der = uacrypto.der_from_x509(cert)
        if der in self._trusted or self._issued_by_trusted(cert):
            return
        self._reject(cert, der, app)
        raise ServiceError(ua.StatusCodes.BadCertificateUntrusted)

    def _reject(self, cert: x509.Certificate, der: bytes, app: ua.ApplicationDescription) -> None:
        thumbprint = cert.fingerprint(hashes.SHA1()).hex()  # OPC UA's thumbprint is SHA-1
        self.rejected_dir.mkdir(parents=True, exist_ok=True)
        path = self.rejected_dir / f"{thumbprint}.der"
        if not path.exists():
            path.write_bytes(der)
        log.warning("OPC UA client certificate of %s (%s) refused: not in the trust list %s; "
                    "saved as %s — move it there to trust it", app.ApplicationUri,
                    cert.subject.rfc4514_string(), self.trusted_dir, path)  # fmt: skip
