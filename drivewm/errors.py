"""The error types the CLI turns into clear messages without a traceback (docs/DESIGN.md section 7)."""


class DrivewmError(Exception):
    """Bad input or configuration: the message names the file or value and what is wrong.

    The CLI prints ``error: <message>`` and exits with status 2, without a traceback.
    Batch stages catch it per item, record it as the item's reason and go on.
    """


class BatchError(DrivewmError):
    """A batch command (curate, import-video, encode, decode, eval, transfer) produced nothing usable.

    The CLI prints ``error: <message>`` and then one line per failed item (``failures``), and exits 2.
    """

    def __init__(self, message: str, failures: list[str]):
        super().__init__(message)
        self.failures = list(failures)
