"""Command-line checks the scripts share: one-line errors, pose values, domain ids, outputs.

Errors are one line (no usage dump); output paths are checked before a run instead of failing
after it; numbers (number_argument) and ROS names (ros_name_argument) as argparse types.
"""
from __future__ import annotations

import argparse
import math
import os
import re
import sys
from pathlib import Path
from typing import Callable, NoReturn, Sequence

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(REPO))

from amr_common.ros.ros_env import check_domain_id  # noqa: E402


class OneLineArgumentParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line, `prog: error: message`, exit code 2.

    argparse prints the whole usage before the message (11 lines for run_sim.py), which buries
    it; --help still shows the usage.
    """

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (--help lists the options)\n")


# '-1.0,2,0' or '-.5': a value, not an option (argparse only takes plain negative numbers).
_NEGATIVE_VALUE = re.compile(r"^-\.?\d")


def join_negative_values(argv: Sequence[str] | None, options: Sequence[str]) -> list[str]:
    """Glue `--start -1.0,-1.0,1.57` into `--start=-1.0,-1.0,1.57` for each of `options`.

    argparse reads a value starting with '-' as the next option unless it is a single negative
    number, so a pose typed as usual would be refused.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    joined: list[str] = []
    index = 0
    while index < len(args):
        item = args[index]
        if item in options and index + 1 < len(args) and _NEGATIVE_VALUE.match(args[index + 1]):
            joined.append(f"{item}={args[index + 1]}")
            index += 2
        else:
            joined.append(item)
            index += 1
    return joined


def domain_id_argument(text: str) -> int:
    """The argparse type of --domain-id: an integer DDS accepts (0-232)."""
    try:
        return check_domain_id(text, "the domain id")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def number_argument(kind: type = float, minimum: float = 0.0, *, above: bool = False,
                    maximum: float = math.inf) -> Callable[[str], float]:
    """An argparse type: a finite `kind` (int or float) >= minimum (> if `above`), <= maximum.

    -1, nan or inf for a timeout or a count become a one-line error before anything runs.
    """
    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"'{text}' is not {'an integer' if kind is int else 'a number'}") from None
        low = f"> {minimum:g}" if above else f">= {minimum:g}"
        if not (math.isfinite(value) and (value > minimum if above else value >= minimum)
                and value <= maximum):
            high = "" if maximum == math.inf else f" and <= {maximum:.15g}"
            raise argparse.ArgumentTypeError(f"must be {low}{high} (got '{text}')")
        return value

    return parse


def ros_name_argument(what: str) -> Callable[[str], str]:
    """An argparse type: a ROS topic (or node, as its services' prefix) name, made absolute."""
    def parse(text: str) -> str:
        from rclpy.exceptions import InvalidTopicNameException
        from rclpy.validate_full_topic_name import validate_full_topic_name
        name = text if text.startswith("/") else "/" + text
        try:
            validate_full_topic_name(name)
        except InvalidTopicNameException as exc:
            reason = str(exc).split(":", 1)[-1].split("\n")[0].strip().rstrip(":")
            raise argparse.ArgumentTypeError(f"'{text}' is not a {what} name: {reason}") from None
        return name

    return parse


def add_domain_id_option(parser: argparse.ArgumentParser,
                         help: str = "ROS_DOMAIN_ID (default: the environment's)") -> None:
    """--domain-id N (0-232) of a script that joins an existing graph; see use_domain_id."""
    parser.add_argument("--domain-id", type=domain_id_argument, default=None, help=help)


def use_domain_id(args: argparse.Namespace) -> None:
    """Join the --domain-id graph (sets ROS_DOMAIN_ID; call before rclpy.init); else keep it."""
    if args.domain_id is not None:
        os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)


def check_output_file(path: str | os.PathLike, what: str) -> Path:
    """`path` if a file can be written there after the run; ValueError (one line) if not.

    Creates missing parent folders (the run would create them anyway); leaves no file behind.
    """
    target = Path(path).expanduser()
    if target.is_dir():
        raise ValueError(f"{what} '{path}' is a folder: give a file name")
    blocking = next((p for p in target.parents if p.exists() and not p.is_dir()), None)
    if blocking is not None:
        raise ValueError(f"{what} '{path}': '{blocking}' is a file, not a folder")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"{what} '{path}': cannot create its folder: "
                         f"{exc.strerror or exc}") from None
    existed = target.exists()
    try:
        with open(target, "ab"):
            pass
    except OSError as exc:
        raise ValueError(f"{what} '{path}' cannot be written: {exc.strerror or exc}") from None
    if not existed:
        target.unlink()
    return target


def check_output_folder(path: str | os.PathLike, what: str) -> Path:
    """`path` as a writable folder (created if missing); ValueError (one line) if it cannot be."""
    target = Path(path).expanduser()
    if target.exists() and not target.is_dir():
        raise ValueError(f"{what} '{path}' is a file, not a folder")
    try:
        target.mkdir(parents=True, exist_ok=True)
        probe = target / f".write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ValueError(f"{what} '{path}' cannot be written: {exc.strerror or exc}") from None
    return target


def plot_file(path: str | os.PathLike) -> Path:
    """The file a plot is saved to: PNG when the name has no suffix.

    ValueError for a format matplotlib cannot write.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    target = Path(path)
    if not target.suffix:
        return target.with_name(target.name + ".png")
    formats = FigureCanvasAgg.get_supported_filetypes()
    if target.suffix[1:].lower() not in formats:
        raise ValueError(f"--plot '{path}': matplotlib cannot write '{target.suffix}' files "
                         f"(use one of {', '.join('.' + f for f in sorted(formats))})")
    return target


def recording_file(path: str | os.PathLike) -> Path:
    """The MCAP file a recording is written to: .mcap when the name has no suffix.

    ValueError for another suffix (a recording is always MCAP).
    """
    target = Path(path)
    if target.is_dir():
        return target  # check_output_file says what is wrong with it
    if not target.suffix:
        return target.with_name(target.name + ".mcap")
    if target.suffix.lower() != ".mcap":
        raise ValueError(f"--record '{path}': recordings are MCAP files: name it .mcap")
    return target


def per_start_path(path: str | os.PathLike, label: str) -> Path:
    """'out/run.png' -> 'out/run-<label>.png': one output file per start of a multi-start run."""
    target = Path(path)
    return target.with_name(f"{target.stem}-{label}{target.suffix}")
