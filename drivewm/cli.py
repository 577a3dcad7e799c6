"""The ``drivewm`` command: one sub-command per stage (docs/DESIGN.md section 8).

Each stage owns a small ``commands.py`` module with ``register(subparsers)``: it adds its
sub-parser(s) and sets ``func(args) -> int | None``. Those modules import only argparse-level
things at the top, so ``drivewm --help`` stays fast; the heavy imports happen inside ``func``.
This file parses, dispatches and turns :class:`DrivewmError` into one line and exit status 2 (a
:class:`BatchError`, a batch that produced nothing usable, adds one line per failed item). It is also the
one place that does so for an ``OSError`` of the file system (full, read-only, no permission:
drivewm.errors.storage_message), naming the path; other ``OSError`` s are bugs and keep their traceback.
A command that declares ``lock_out`` (``set_defaults(lock_out="generate")``) runs holding its ``--out``
folder's lock (drivewm.lock), so two runs never write one output folder.
"""

from __future__ import annotations

import argparse
import importlib
import os
import select
import sys

from drivewm import __version__
from drivewm.errors import BatchError, DrivewmError, storage_message

#: Modules that register sub-commands, in help order.
COMMAND_MODULES = (
    "drivewm.sim.commands",  # simulate
    "drivewm.logs.commands",  # view
    "drivewm.layout.commands",  # layout
    "drivewm.curate.commands",  # curate, import-video
    "drivewm.tokenizer.commands",  # tokenizer train|encode|decode|eval
    "drivewm.diffusion.commands",  # pretrain
    "drivewm.ar.commands",  # ar train|eval
    "drivewm.multiview.commands",  # posttrain
    "drivewm.generate.commands",  # generate, rollout
    "drivewm.eval.commands",  # eval
    "drivewm.eval.judge_commands",  # judge train|eval|score
    "drivewm.multiverse.commands",  # multiverse
    "drivewm.transfer.commands",  # transfer, transfer-train
    "drivewm.product.quickstart",  # quickstart
    "drivewm.product.worldmodel",  # worldmodel train|figures|export
)


class OneLineErrors(argparse.ArgumentParser):
    """argparse that reports a bad flag like every other bad input: one ``error: ...`` line, exit 2."""

    def error(self, message: str):
        print(f"error: {self.prog}: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineErrors(prog="drivewm", description="Multi-camera driving world models.")
    parser.add_argument("--version", action="version", version=f"drivewm {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:  # a stage not built yet: its commands are simply absent
                continue
            raise
        module.register(sub)
    return parser


#: Exit status of a command whose reader went away (``drivewm ... | head``): a shell's for SIGPIPE.
BROKEN_PIPE_STATUS = 128 + 13


def main(argv: list[str] | None = None) -> int:
    try:
        code = _main(argv)
    except BrokenPipeError:
        if not _stdout_closed():  # another pipe (a worker's, a socket's): a fault, not a reader gone
            raise
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # so the exit's flush cannot raise again
        return BROKEN_PIPE_STATUS
    # A torchrun worker that trained leaves without finalisation (exit_worker says why). Looked up,
    # not imported: only a command that trained has loaded it, and the CLI itself stays free of torch.
    if (distributed := sys.modules.get("drivewm.train.distributed")) is not None:
        distributed.exit_worker(code)
    return code


def _stdout_closed() -> bool:
    """Whether the reader of stdout went away (a pipe's write end polls as an error once its read end
    is closed)."""
    try:
        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poll.poll(0))
    except (AttributeError, OSError, ValueError):  # no fileno (captured), or no poll on this platform
        return False


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version and bad flags end here; hand back the status
        return int(exc.code or 0)
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    try:
        return _run(args)
    except DrivewmError as exc:
        print(f"error: {exc}", file=sys.stderr)
        for line in exc.failures if isinstance(exc, BatchError) else ():
            print(f"  {line}", file=sys.stderr)
        return 2
    except OSError as exc:
        if (message := storage_message(exc)) is None:
            raise
        print(f"error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


def _run(args: argparse.Namespace) -> int:
    """The command, holding its output folder's lock when it declares ``lock_out`` (a dry run writes nothing)."""
    if getattr(args, "lock_out", None) is None or getattr(args, "dry_run", False):
        return int(args.func(args) or 0)
    from drivewm.lock import folder_lock

    with folder_lock(args.out, args.lock_out):
        return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
