"""``millwatch zenoh-certs``: a CA kept across runs, one certificate per role, private keys
readable by their owner only, the router named as its clients reach it."""

from __future__ import annotations

import stat
from pathlib import Path

from cryptography import x509
from cryptography.x509.oid import NameOID

from millwatch.cli.main import main

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"


def _cert(path: Path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def test_a_ca_and_a_certificate_per_role_signed_by_it(tmp_path, capsys):
    argv = ["zenoh-certs", str(tmp_path), "--router-host", "zr.plant.example", "--mills",
            str(MILLS), "--gateway", "north/ball-7"]  # fmt: skip
    assert main(argv) == 0
    names = {"router", "worker", "api", "gateway.rustenburg.sag-5200-lrs",
             "gateway.rustenburg.ball-dual-lrs", "gateway.carletonville.rod-1100-grid",
             "gateway.north.ball-7"}  # fmt: skip
    assert {Path(p).name for p in capsys.readouterr().out.split()} == {f"{n}.pem" for n in names}
    ca = _cert(tmp_path / "ca.pem")
    for name in names:
        cert = _cert(tmp_path / f"{name}.pem")
        assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == name
        cert.verify_directly_issued_by(ca)
        mode = stat.S_IMODE((tmp_path / f"{name}-key.pem").stat().st_mode)
        assert mode == 0o600
    alt = _cert(tmp_path / "router.pem").extensions.get_extension_for_class(
        x509.SubjectAlternativeName
    )
    assert set(alt.value.get_values_for_type(x509.DNSName)) == {"localhost", "zr.plant.example"}


def test_a_second_run_keeps_the_ca_and_the_certificates_unless_renewed(tmp_path, capsys):
    assert main(["zenoh-certs", str(tmp_path)]) == 0
    ca, worker = (tmp_path / "ca.pem").read_bytes(), (tmp_path / "worker.pem").read_bytes()
    assert main(["zenoh-certs", str(tmp_path)]) == 0
    assert (tmp_path / "worker.pem").read_bytes() == worker
    assert main(["zenoh-certs", str(tmp_path), "--renew"]) == 0
    assert (tmp_path / "ca.pem").read_bytes() == ca
    assert (tmp_path / "worker.pem").read_bytes() != worker
    assert "keeping the CA" in capsys.readouterr().err
