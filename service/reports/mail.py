"""Mail a monthly report: one message per mill and month, the report files attached.

Standard library only (:mod:`smtplib`, :mod:`email`). The connection is upgraded with STARTTLS
before anything else is said when ``starttls`` is on (the default; the server's certificate is
checked against the system's CAs or ``ca_file``), then the sender logs in when a ``username``
is set. The password comes from :meth:`~millwatch.settings.MailSettings.password` at send time
and is never logged nor put in an error message (smtplib's debug output is never switched on).

Errors are :class:`MailError`, whose message names the server and the step that failed (connect,
STARTTLS, login, send) — the month-end job retries them and then raises the
``report_delivery`` alarm with that message. A recipient refused while others were accepted is
not an error here (the message went out): :func:`send_message` returns the refused ones, and the
month-end job alarms them without sending again.
"""

from __future__ import annotations

import logging
import smtplib
import ssl
from collections.abc import Mapping
from email.message import EmailMessage
from email.utils import formatdate, make_msgid
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from millwatch.settings import MailSettings

__all__ = ["MIME_TYPES", "MailError", "report_message", "send_message"]

log = logging.getLogger(__name__)

#: MIME type of each attached file extension.
MIME_TYPES: dict[str, tuple[str, str]] = {
    "pdf": ("application", "pdf"),
    "html": ("text", "html"),
    "csv": ("text", "csv"),
    "zip": ("application", "zip"),
}


class MailError(RuntimeError):
    """A report mail that could not be sent; the message names the server and the step."""


def report_message(
    mail: MailSettings,
    *,
    mill_id: str,
    site: str,
    month: str,
    files: Mapping[str, bytes],
    paths: Mapping[str, str] | None = None,
) -> EmailMessage:
    """The mail of one mill's report of ``month``: a short plain-text body saying what is
    attached and where the files are kept, and the files of the formats ``mail.attach`` found
    in ``files`` (file extension → bytes: the ``csv`` format is the ``zip`` file of its tables,
    :data:`~millwatch.reports.files.EXTENSIONS`) as attachments named ``<mill>-<YYYY-MM>.<ext>``."""
    msg = EmailMessage()
    msg["Subject"] = f"millwatch monthly report {month}: mill {mill_id} ({site})"
    msg["From"] = mail.sender
    msg["To"] = ", ".join(mail.recipients)
    msg["Date"] = formatdate(localtime=False)
    msg["Message-ID"] = make_msgid(domain=mail.sender.rsplit("@", 1)[-1])
    from millwatch.reports.files import EXTENSIONS

    attached = [EXTENSIONS[f] for f in mail.attach if EXTENSIONS[f] in files]
    lines = [
        f"The monthly damage report of mill {mill_id} (site {site}) for {month} "
        f"(the site's local calendar month) is attached: "
        f"{', '.join(ext.upper() for ext in attached) or 'no files'}.",
        "",
        "It covers starts against the norm, fatigue damage by phase and component, "
        "steady-state oscillation and bending trends, harmonics, alarms and data quality "
        "(Diering 2011 §10.6).",
    ]
    if paths:
        lines += ["", "Files kept by the service:"] + [f"  {p}" for p in paths.values()]
    lines += ["", "-- millwatch (sent automatically after the month end)"]
    msg.set_content("\n".join(lines))
    for ext in attached:
        maintype, subtype = MIME_TYPES.get(ext, ("application", "octet-stream"))
        msg.add_attachment(
            files[ext], maintype=maintype, subtype=subtype, filename=f"{mill_id}-{month}.{ext}"
        )
    return msg


def send_message(mail: MailSettings, msg: EmailMessage) -> dict[str, str]:
    """Send ``msg`` through ``mail``'s server (module docstring); :class:`MailError` on any
    failure, naming the step. When the server takes the message for some recipients and
    refuses others, the message is delivered: the refused ones are returned (address →
    the server's reply) for the caller to report, not raised — sending again would give the
    others a second copy."""
    where = f"SMTP server {mail.host}:{mail.port}"
    step = "connect"
    try:
        with smtplib.SMTP(mail.host, mail.port, timeout=mail.timeout_s) as smtp:
            smtp.ehlo()
            if mail.starttls:
                step = "STARTTLS"
                context = ssl.create_default_context(
                    cafile=None if mail.ca_file is None else str(mail.ca_file)
                )
                smtp.starttls(context=context)
                smtp.ehlo()
            if mail.username is not None:
                step = "login"
                password = mail.password()
                if password is None:
                    raise MailError(
                        f"{where}: no password for user {mail.username!r} (set "
                        f"reports.mail.password_file or the environment variable "
                        f"{mail.password_env})"
                    )
                smtp.login(mail.username, password)
            step = "send"
            refused = smtp.send_message(msg)
    except MailError:
        raise
    except smtplib.SMTPAuthenticationError as exc:
        raise MailError(f"{where}: login as {mail.username!r} refused ({exc.smtp_code})") from None
    except (smtplib.SMTPException, OSError) as exc:
        raise MailError(f"{where}: {step} failed: {_reason(exc)}") from None
    log.info("mailed %s to %d recipient(s) via %s", msg["Subject"],
             len(mail.recipients) - len(refused), where)  # fmt: skip
    return {rcpt: f"{code} {_text(reply)}".strip() for rcpt, (code, reply) in refused.items()}


def _text(reply: bytes | str) -> str:
    return reply.decode("utf-8", "replace") if isinstance(reply, bytes) else str(reply)


def _reason(exc: BaseException) -> str:
    """A one-line cause that cannot carry the password (server replies and OS errors only)."""
    if isinstance(exc, smtplib.SMTPResponseException):
        text = exc.smtp_error.decode("utf-8", "replace") if isinstance(
            exc.smtp_error, bytes) else str(exc.smtp_error)  # fmt: skip
        return f"{exc.smtp_code} {text}".strip()
    return f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
