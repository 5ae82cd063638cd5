"""The ``gpusim`` command line. Each command lives in its own module."""

from __future__ import annotations

import os
import signal
import sys
import threading

from gpusim import __version__, interrupt
from gpusim.cli import (config_cmd, info_cmd, replay_cmd, report_cmd, run_cmd, schemes_cmd, show_cmd,
                        trace_cmd)
from gpusim.cli.common import Parser
from gpusim.errors import GpusimError

COMMANDS = (run_cmd, config_cmd, report_cmd, trace_cmd, info_cmd, show_cmd, replay_cmd, schemes_cmd)


def build_parser() -> Parser:
    parser = Parser(prog="gpusim", description="Cycle-approximate simulator of multi-fragment rendering hardware.")
    parser.add_argument("--version", action="version", version=f"gpusim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for module in COMMANDS:
        module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "run", None):
        parser.print_help(sys.stderr)
        return 2
    previous = {}
    interrupt.clear()
    if threading.current_thread() is threading.main_thread():      # SIGTERM stops a command like Ctrl-C: the
        previous = {sig: signal.signal(sig, interrupt.handle)      # half-written outputs are removed; the stop
                    for sig in (signal.SIGINT, signal.SIGTERM)     # is recorded, so a lost one still stops;
                    if signal.getsignal(sig) is not signal.SIG_IGN}   # a signal ignored by the caller stays so
    try:
        return args.run(args)
    except GpusimError as exc:
        print(f"gpusim: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gpusim: interrupted; no output was left half-written", file=sys.stderr)
        return 130
    except MemoryError:                # a size in the input beyond this machine (outputs are atomic: none left)
        print("gpusim: error: out of memory: the input asks for more than this machine holds; use a smaller "
              "screen, scene, trace or GPU", file=sys.stderr)
        return 2
    except BrokenPipeError:            # the reader went away (e.g. '| head'): stop quietly, like other tools
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as exc:             # a path that is a file, not a folder; no permission; a full disk
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"gpusim: error: {where}{exc.strerror or exc}; check the path, its permissions and the free space",
              file=sys.stderr)
        return 2
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        interrupt.clear()


if __name__ == "__main__":
    sys.exit(main())
