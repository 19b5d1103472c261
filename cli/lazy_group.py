"""A click group whose commands live in modules imported only when a command is looked up.

``streetaug batch`` then imports the batch command's module and not the others'; ``streetaug --help`` imports
each command module to print its one-line help, so a command module keeps its heavy imports (torch, scipy,
the dataset reader, the pipeline) inside the command body.
"""

from __future__ import annotations

import importlib

import click


class LazyGroup(click.Group):
    """A ``click.Group`` with commands given as ``{name: "module:attribute"}``, imported on first look-up.

    Commands added the usual way (``@group.command``) work as before; the listing is the union, sorted
    (as ``click.Group`` sorts it).
    """

    def __init__(self, *args, lazy_commands: dict[str, str] | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.lazy_commands = dict(lazy_commands or {})

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*self.commands, *self.lazy_commands})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.commands and cmd_name in self.lazy_commands:
            module_name, attribute = self.lazy_commands[cmd_name].split(":")
            command = getattr(importlib.import_module(module_name), attribute)
            if not isinstance(command, click.Command) or command.name != cmd_name:
                raise RuntimeError(f"{self.lazy_commands[cmd_name]} is not the click command {cmd_name!r}")
            self.add_command(command)
        return super().get_command(ctx, cmd_name)
