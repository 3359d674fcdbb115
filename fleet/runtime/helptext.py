"""How `--help` reads, in the `fleet` command line and in every process that starts itself
(`python -m dispatcher`): every option with its default, descriptions wrapped by paragraph, and
the texts that several commands share (the strategies)."""

from __future__ import annotations

import argparse
import re
import textwrap

# One line each, for `fleet run --help` (docs/dispatching.md has the equations).
STRATEGIES = {
    "ann": "comprehensive, plus a trained network's estimate of the traffic each cluster "
           "will meet (seed 000's best; weights ship for paper, small and hall)",
    "comprehensive": "balance and traffic together: clusters with much work left, reached "
                     "soon, with their target free",
    "greedy": "the cluster reached soonest (travel time only; the far clusters get a bonus)",
    "traffic": "traffic-jam removal: travel time, and how long other forklifts hold the "
               "target's cells after arrival",
    "balance": "the cluster with the most stacks still to do",
    "nearest": "order missions only (seed 002): each order's shelf to the nearest idle AGV, "
               "then the nearest free packing station and the nearest vacant slot",
}


def strategies_epilog() -> str:
    width = max(map(len, STRATEGIES))
    lines = [f"  {name:<{width}}  {text}" for name, text in STRATEGIES.items()]
    return "strategies (how the dispatcher picks each vehicle's next goal):\n" + \
        "\n".join(lines)


class HelpFormatter(argparse.HelpFormatter):
    """Options show their default unless their help already says it; descriptions and
    epilogs keep their paragraphs, and an indented paragraph is a list of `term  text`
    items, each wrapped under its text."""

    def __init__(self, prog: str, max_help_position: int = 30, **kwargs) -> None:
        super().__init__(prog, max_help_position=max_help_position, **kwargs)

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        paragraphs = []
        for paragraph in textwrap.dedent(text).strip().split("\n\n"):
            lines = paragraph.splitlines()
            if any(line.startswith(" ") for line in lines[1:]):
                paragraphs.append("\n".join(_list_item(line, width, indent) for line in lines))
            else:
                paragraphs.append(textwrap.fill(" ".join(paragraph.split()), width,
                                                initial_indent=indent,
                                                subsequent_indent=indent))
        return "\n\n".join(paragraphs)

    def add_argument(self, action: argparse.Action) -> None:
        super().add_argument(action)
        if isinstance(action, argparse._SubParsersAction):
            # argparse measures the commands one indent short of where it prints them
            longest = max(map(len, action.choices), default=0)
            self._action_max_length = max(self._action_max_length, longest +
                                          self._current_indent + 2 * self._indent_increment)

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if shows_default(action) and "default" not in text:
            text += " (default %(default)s)"
        return text


def _list_item(line: str, width: int, indent: str) -> str:
    item = re.match(r"(\s+\S+\s+)(.*)", line)
    if item is None:  # the list's heading
        return indent + line
    head = indent + item[1]
    return textwrap.fill(item[2], width, initial_indent=head,
                         subsequent_indent=" " * len(head))


def shows_default(action: argparse.Action) -> bool:
    """Whether an option's default means something to print (a flag's is just 'off')."""
    return (bool(action.option_strings) and action.nargs != 0 and not action.required
            and action.default not in (None, argparse.SUPPRESS, [], False))


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose help reads as HelpFormatter says; its subcommands' parsers
    are Parsers too (argparse makes them of the parent's class)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
