"""The one error type the CLI turns into a clear one-line message (docs/DESIGN.md section 7)."""


class DrivewmError(Exception):
    """Bad input or configuration: the message names the file or value and what is wrong.

    The CLI prints ``error: <message>`` and exits with status 2, without a traceback.
    Batch stages catch it per item, record it as the item's reason and go on.
    """
