"""mkdocs hook: the reference pages generated from the code before every build.

The CLI page comes from the argument parser, the scenario-field page from each system's
schema and the status page from :class:`gnc_jax.Status` and the CLI's exit codes, so none of
them can drift from what the package does. The generated files are not committed.
"""

import inspect
import pathlib

GENERATED = ("cli.md", "fields.md", "status.md")


def _cli() -> str:
    from gnc_jax import cli

    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    out = [
        "# Command line: `gnc-jax`\n",
        "Generated from the argument parser (`gnc_jax.cli.build_parser`).\n",
        "```text\n" + parser.format_help().replace("gnc-jax", "gnc-jax", 1) + "```\n",
    ]
    for name, p in sub.choices.items():
        out.append(f"## `gnc-jax {name}`\n\n```text\n{p.format_help()}```\n")
    return "\n".join(out)


def _fields() -> str:
    from gnc_jax.systems import systems

    out = [
        "# Scenario fields\n",
        "Every field of every system's scenario schema, with its default, allowed range and units "
        "(generated from the schema, as `gnc-jax list --fields` prints it). A scenario TOML sets "
        "any of them; `--set section.field=value` overrides one on the command line.\n",
    ]
    for kind, system in systems().items():
        out.append(f"## `{kind}`\n\n{system.description}\n")
        out.append("| field | default | allowed | meaning |\n|---|---|---|---|")
        for section, fields in system.schema().items():
            for name, f in fields.items():
                doc = (f.doc or "").replace("|", "\\|")
                allowed = str(f.allowed()).replace("|", "\\|")
                default = repr(f.default).replace("|", "\\|")
                out.append(f"| `{section}.{name}` | `{default}` | {allowed} | {doc} |")
        out.append("")
    return "\n".join(out)


def _status() -> str:
    from gnc_jax import Status, cli

    src = inspect.getsource(Status)
    rows = []
    for s in Status:
        lines = src.splitlines()
        i = next((i for i, ln in enumerate(lines) if ln.strip().startswith(f"{s.name} =")), None)
        words = [] if i is None else [lines[i].partition("#")[2].strip()]
        for ln in lines[i + 1 :] if i is not None else []:  # the comment's continuation lines
            if not ln.strip().startswith("#"):
                break
            words.append(ln.strip().lstrip("#").strip())
        rows.append(f"| {int(s)} | `{s.name}` | {' '.join(words)} |")
    exits = [
        (0, "the study ran and at most `--max-failed` of its runs failed"),
        (cli.EXIT_REFUSED, "bad input or a runaway cost, refused before anything was compiled"),
        (cli.EXIT_FAILED_RUNS, "the study ran, its results were written, too many runs failed"),
        (cli.EXIT_INTERNAL, "an unexpected error inside gnc_jax (a bug)"),
        (130, "interrupted (Ctrl-C); a study with `--out` keeps its finished chunks"),
    ]
    return "\n".join(
        [
            "# Run status and exit codes\n",
            "A run whose status is not `ok` is counted in `failed` (and `failed_by_status`) and "
            "left out of every statistic.\n",
            "| code | status | meaning |\n|---|---|---|",
            *rows,
            "\n## Exit codes of `gnc-jax`\n",
            "| code | meaning |\n|---|---|",
            *[f"| {c} | {m} |" for c, m in exits],
            "",
        ]
    )


def _benchmark_figures(docs: pathlib.Path) -> None:
    """The figures ``python -m benchmarks`` wrote, copied beside the benchmarks page."""
    import shutil

    out = docs / "benchmark-figures"
    out.mkdir(exist_ok=True)
    for png in sorted((docs.parent / "benchmarks" / "figures").glob("*.png")):
        if not (out / png.name).exists() or (out / png.name).read_bytes() != png.read_bytes():
            shutil.copyfile(png, out / png.name)


def on_pre_build(config, **kwargs):
    _benchmark_figures(pathlib.Path(config["docs_dir"]))
    ref = pathlib.Path(config["docs_dir"]) / "reference"
    ref.mkdir(exist_ok=True)
    for name, make in zip(GENERATED, (_cli, _fields, _status)):
        text = make()
        path = ref / name
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
