"""A run's own certificate authority for the links between the routers of several hosts
(`fleet run --hosts FILE --secure`): each router gets a key and a certificate whose common
name is its process name (`router`, `router-NAME`), signed by a CA made for the run, and the
routers link over TLS with certificates both ways (zenoh's `enable_mtls`), so each router's
access control knows the other by its certificate (fleet/runtime/access.py)."""

from __future__ import annotations

import datetime
import ipaddress
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from fleet.runtime.access import TlsFiles, write_private

# Valid from a day before the run to a year after: the hosts' clocks need not agree to the
# minute, and a long session can link again; the CA's key is gone once the run has its
# certificates, so a wide window lets no one sign more.
VALID = datetime.timedelta(days=365)
SKEW = datetime.timedelta(days=1)


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _san(address: str) -> x509.GeneralName:
    """The address the others reach the router at, as a certificate names it."""
    try:
        return x509.IPAddress(ipaddress.ip_address(address))
    except ValueError:
        return x509.DNSName(address)


class RunAuthority:
    """A CA of one run: its key only in memory, its certificate written beside each router's
    key and certificate it issues."""

    def __init__(self, run: str) -> None:
        self.key = ec.generate_private_key(ec.SECP256R1())
        self.name = _name(f"fleet run {run}")
        self.certificate = self._sign(self.name, self.key, x509.BasicConstraints(
            ca=True, path_length=0))

    def issue(self, common_name: str, address: str, folder: Path) -> TlsFiles:
        """A key and a certificate for the router `common_name` that listens at `address`,
        written in `folder` with the CA's certificate (`ca.pem`)."""
        ca = folder / "ca.pem"
        ca.write_bytes(self.certificate.public_bytes(serialization.Encoding.PEM))
        key = ec.generate_private_key(ec.SECP256R1())
        certificate = self._sign(_name(common_name), key, x509.BasicConstraints(
            ca=False, path_length=None), x509.SubjectAlternativeName([_san(address)]))
        cert_path = folder / f"{common_name}.pem"
        cert_path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
        key_path = write_private(folder / f"{common_name}.key", key.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption()).decode())
        return TlsFiles(ca, cert_path, key_path)

    def _sign(self, subject: x509.Name, key: ec.EllipticCurvePrivateKey,
              constraints: x509.BasicConstraints,
              names: x509.SubjectAlternativeName | None = None) -> x509.Certificate:
        """`key`'s certificate for `subject`, signed by this CA, valid around now."""
        now = datetime.datetime.now(datetime.UTC)
        builder = (x509.CertificateBuilder().subject_name(subject).issuer_name(self.name)
                   .public_key(key.public_key()).serial_number(x509.random_serial_number())
                   .not_valid_before(now - SKEW).not_valid_after(now + VALID)
                   .add_extension(constraints, critical=True))
        if names is not None:
            builder = builder.add_extension(names, critical=False)
        return builder.sign(self.key, hashes.SHA256())
