"""The command-line page: every command and option of the `mapqual` typer app, from the app."""

from __future__ import annotations

from typing import Any

import typer.main

from mapqual.reference.comments import cell, code_cell, prose

_HEAD = """# Command line

Every command of `mapqual` and every option it takes, read from the command-line app itself
each time the manual is built. `mapqual COMMAND --help` prints the same on the terminal.
Bad input is refused with one line on stderr (`mapqual: error: ...`) and exit code 2.
"""


# typer ships its own copy of click (typer._click), so commands and parameters are read by
# their attributes (`commands`, `param_type_name`), not by click's classes
Command = Any


def commands() -> list[tuple[str, Command]]:
    """(full name, command) of every command, groups included, in the order of the names."""
    root = typer.main.get_command(_app())
    out: list[tuple[str, Command]] = []

    def walk(name: str, cmd: Command) -> None:
        out.append((name, cmd))
        if _is_group(cmd):
            for sub in sorted(cmd.commands):
                walk(f"{name} {sub}", cmd.commands[sub])

    walk("mapqual", root)
    return out


def _app() -> typer.Typer:
    from mapqual.cli import app

    return app


def _is_group(cmd: Command) -> bool:
    return isinstance(getattr(cmd, "commands", None), dict)


def _param_row(param: Any, ctx: Any) -> str:
    """One table row, from the help record `--help` prints (names, type, help, default)."""
    record = param.get_help_record(ctx)
    names, help_text = record if record else (param.metavar or param.name, "")
    kind = "argument" if param.param_type_name == "argument" else "option"
    return f"| {code_cell(names)} | {kind} | {cell(help_text)} |"


def _command_section(name: str, cmd: Command) -> str:
    ctx = cmd.context_class(cmd, info_name=name)
    usage = " ".join(cmd.collect_usage_pieces(ctx))
    level = "#" * min(name.count(" ") + 1, 4)
    help_text = prose((cmd.help or "").strip())
    parts = [f"#{level} `{name}`\n", help_text + "\n", f"```\n{name} {usage}\n```\n"]
    params = [p for p in cmd.params if not getattr(p, "hidden", False)]
    if params:
        rows = ["| name | kind | meaning |", "| --- | --- | --- |"]
        rows += [_param_row(p, ctx) for p in params]
        parts.append("\n".join(rows) + "\n")
    if _is_group(cmd):
        subs = ", ".join(f"`{name} {s}`" for s in sorted(cmd.commands))
        parts.append(f"Commands: {subs}.\n")
    return "\n".join(parts)


def cli_page() -> str:
    """The whole command-line page."""
    return "\n".join([_HEAD, *(_command_section(n, c) for n, c in commands())])
