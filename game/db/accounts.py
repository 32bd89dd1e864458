"""Who may do what: therapist and patient accounts, and the audit record of who did what and when.

Accounts are optional: a database without any (a single therapist's laptop) works as before. Once
a therapist account exists, the commands that run ROM tests, accept results, change patients or
limits, write reports or export need a therapist's name and secret; a patient account may only
play its own patient's games. The secret (a password or a PIN of at least 4 characters) is stored
only as a salted scrypt hash (``hashlib.scrypt``, a standard memory-hard KDF; compared in constant
time). Accounts hold no identifying data: a name of the clinic's choosing, a role, and for a
patient the pseudonymous patient ID. Every accepted result, change and export is one row of the
``audit`` table (who, what, which patient, when); a result's acceptance is written in the
result's own transaction, so it is there exactly when the result is, even after a station's queue.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import re
import uuid
from dataclasses import dataclass

from calibration.errors import RehabError
from game.db.database import DatabaseError, utc_now

ROLES = ("therapist", "patient")
#: action -> the roles that may do it (a patient account only for its own patient).
PERMISSIONS: dict[str, tuple[str, ...]] = {
    "play": ("therapist", "patient"),
    "rom_test": ("therapist",),
    "accept": ("therapist",),
    "limits": ("therapist",),
    "progress": ("therapist",),
    "report": ("therapist",),
    "export": ("therapist",),
    "import": ("therapist",),
    "backup": ("therapist",),
    "patients": ("therapist",),
    "accounts": ("therapist",),
}
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,31}$")
_SCRYPT = {"n": 2 ** 14, "r": 8, "p": 1}   # ~50 ms and 16 MB per check: cheap to use, dear to guess


class AccessDenied(RehabError):
    """The account may not do this, or the name or secret is wrong (one line)."""


@dataclass(frozen=True, slots=True)
class Account:
    """A signed-in account: its name, role, and (for a patient) its patient ID."""

    name: str
    role: str
    patient_id: str | None = None

    def may(self, action: str, patient_id: str | None = None) -> bool:
        if self.role not in PERMISSIONS.get(action, ()):
            return False
        return self.role == "therapist" or patient_id is None or patient_id == self.patient_id

    def require(self, action: str, patient_id: str | None = None) -> None:
        """Raise :class:`AccessDenied` unless this account may do ``action`` (for ``patient_id``)."""
        if not self.may(action, patient_id):
            whose = f" for patient {patient_id}" if patient_id and patient_id != self.patient_id else ""
            raise AccessDenied(f"account {self.name} ({self.role}) may not {action.replace('_', ' ')}{whose}: "
                               f"ask a therapist")


def hash_secret(secret: str) -> str:
    """``scrypt$n$r$p$salt$hash`` of a password or PIN (hex), with a new random salt."""
    salt = os.urandom(16)
    digest = hashlib.scrypt(secret.encode("utf-8"), salt=salt, dklen=32, maxmem=64 * 2 ** 20, **_SCRYPT)
    return f"scrypt${_SCRYPT['n']}${_SCRYPT['r']}${_SCRYPT['p']}${salt.hex()}${digest.hex()}"


def verify_secret(secret: str, stored: str) -> bool:
    """Whether ``secret`` matches the stored hash (constant-time comparison; False for a malformed hash)."""
    try:
        kind, n, r, p, salt, digest = stored.split("$")
        if kind != "scrypt":
            return False
        got = hashlib.scrypt(secret.encode("utf-8"), salt=bytes.fromhex(salt), n=int(n), r=int(r), p=int(p),
                             dklen=len(digest) // 2, maxmem=64 * 2 ** 20)
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got.hex(), digest)


def accounts_in_use(db) -> bool:
    """Whether the database has a therapist account (then commands need one)."""
    return db.conn.execute("SELECT 1 FROM accounts WHERE role = 'therapist'").fetchone() is not None


def add_account(db, name: str, role: str, secret: str, patient_id: str | None = None) -> Account:
    """Add an account; a patient account names its (existing) patient. Raises a one-line error."""
    if not _NAME.match(name or ""):
        raise DatabaseError(f"account name {name!r}: use letters, digits, '_', '.', '-' (up to 32), never a "
                            f"patient's real name")
    if role not in ROLES:
        raise DatabaseError(f"role {role!r}: use therapist or patient")
    if len(secret or "") < 4:
        raise DatabaseError("the password or PIN must have at least 4 characters")
    if role == "patient":
        db.require_patient(patient_id or "")
    elif patient_id:
        raise DatabaseError("a therapist account belongs to no patient: leave out --patient")
    cur = db._write("INSERT INTO accounts (name, role, patient_id, secret_hash, created_utc) VALUES (?, ?, ?, ?, ?) "
                    "ON CONFLICT DO NOTHING", (name, role, patient_id if role == "patient" else None,
                                               hash_secret(secret), utc_now()))
    if cur.rowcount != 1:
        raise DatabaseError(f"account {name} already exists in {db.path}")
    return Account(name, role, patient_id if role == "patient" else None)


def authenticate(db, name: str, secret: str) -> Account:
    """The account ``name`` if ``secret`` is its password or PIN; else :class:`AccessDenied` (one line)."""
    row = db.conn.execute("SELECT role, patient_id, secret_hash FROM accounts WHERE name = ?", (name,)).fetchone()
    if row is None or not verify_secret(secret, row[2]):
        raise AccessDenied(f"wrong account name or password/PIN for {name!r} in {db.path}")
    return Account(name, row[0], row[1])


def accounts(db) -> list[Account]:
    return [Account(*r) for r in db.conn.execute("SELECT name, role, patient_id FROM accounts ORDER BY name")]


def record(db, account: str, action: str, patient_id: str | None, what: str, *, uid: str | None = None) -> None:
    """One audit row in its own transaction (``uid`` makes it idempotent)."""
    db._write("INSERT INTO audit (uid, at_utc, account, action, patient_id, what) VALUES (?, ?, ?, ?, ?, ?) "
              "ON CONFLICT DO NOTHING", (uid or uuid.uuid4().hex, utc_now(), account or "-", action, patient_id, what))


@dataclass(frozen=True, slots=True)
class AuditRow:
    at_utc: str
    account: str
    action: str
    patient_id: str | None
    what: str


def audit_rows(db, patient_id: str | None = None) -> list[AuditRow]:
    where, params = ("WHERE patient_id = ?", (patient_id,)) if patient_id else ("", ())
    return [AuditRow(*r) for r in db.conn.execute(
        f"SELECT at_utc, account, action, patient_id, what FROM audit {where} ORDER BY at_utc, id", params)]
