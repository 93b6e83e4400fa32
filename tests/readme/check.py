#!/usr/bin/env python3
"""The README's examples (or another document's), run as written against a live server.

    python3 tests/readme/check.py BASE_URL [README.md | docs/manual.md] [--write]

Every fenced ```sh block that follows a `<!-- readme-test -->` line is run with bash (`set -euo
pipefail`) in a fresh directory holding `target/release`, a link to the directory of the binary
under test (BOUNCEWEAR_BIN_DIR, by default the repository's `target/release`), so that
`target/release/bouncewear` runs as in the README and files the example writes are thrown away;
that directory is on the PATH, and the README's address `http://127.0.0.1:8080` is replaced by
BASE_URL. It must succeed, and when a ```text block follows
under `<!-- readme-output -->`, the output must have the documented shape, line by line: the same
JSON keys and value types (numbers may differ), or for other lines the same fields with the same
words (numbers may differ). Under `<!-- readme-output exact -->` the output must be the one shown,
to the character (deterministic commands: what the README shows is what a user gets).

With `--write`, each output block whose example ran and kept its shape is replaced by the output
of this run, so that the document shows what the build under test prints.
"""

import json
import os
import re
import subprocess
import sys
import tempfile

README_BASE = "http://127.0.0.1:8080"
NUMBER = re.compile(r"-?\d+(\.\d+)?([eE][-+]?\d+)?")


def blocks(text):
    """(script, expected output or None, exact?, line number, the output's line span or None) for
    each marked block."""
    lines = text.split("\n")
    found = []
    for i, line in enumerate(lines):
        if line.strip() != "<!-- readme-test -->":
            continue
        start = i + 1
        assert lines[start].startswith("```sh"), f"line {start + 1}: a ```sh block must follow"
        end = lines.index("```", start + 1)
        script = "\n".join(lines[start + 1:end])
        expected, exact, span = None, False, None
        rest = [j for j in range(end + 1, min(end + 4, len(lines))) if lines[j].strip()]
        marker = lines[rest[0]].strip() if rest else ""
        if marker in ("<!-- readme-output -->", "<!-- readme-output exact -->"):
            exact = "exact" in marker
            out_start = rest[0] + 1
            assert lines[out_start].startswith("```"), f"line {out_start + 1}: an output block must follow"
            out_end = lines.index("```", out_start + 1)
            expected = lines[out_start + 1:out_end]
            span = (out_start + 1, out_end)
        found.append((script, expected, exact, start + 1, span))
    return found


def shape(value):
    """The shape of a JSON value: keys and types, numbers as one type."""
    if isinstance(value, dict):
        return {key: shape(item) for key, item in value.items()}
    if isinstance(value, list):
        return [shape(value[0])] if value else []
    if isinstance(value, bool) or value is None:
        return type(value).__name__
    if isinstance(value, (int, float)):
        return "number"
    return "string"


def same_shape(actual, documented):
    try:
        return shape(json.loads(actual)) == shape(json.loads(documented))
    except json.JSONDecodeError:
        words = lambda line: [NUMBER.sub("#", w) for w in re.split(r"[\s,]+", line.strip())]
        return words(actual) == words(documented)


def main():
    args = [a for a in sys.argv[1:] if a != "--write"]
    write = "--write" in sys.argv[1:]
    base = args[0].rstrip("/")
    readme = args[1] if len(args) > 1 else "README.md"
    # The repository's root (this file is tests/readme/check.py), whichever document is checked.
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    bin_dir = os.path.abspath(os.environ.get("BOUNCEWEAR_BIN_DIR", os.path.join(root, "target", "release")))
    env = {**os.environ, "PATH": bin_dir + os.pathsep + os.environ["PATH"]}
    text = open(readme, encoding="utf-8").read()
    found = blocks(text)
    assert found, "no README example is marked for testing"
    failures = 0
    replacements = []
    for script, expected, exact, line, span in found:
        with tempfile.TemporaryDirectory(prefix="bouncewear-readme-") as scratch:
            os.mkdir(os.path.join(scratch, "target"))
            os.symlink(bin_dir, os.path.join(scratch, "target", "release"))
            run = subprocess.run(["bash", "-euo", "pipefail", "-c", script.replace(README_BASE, base)],
                                 cwd=scratch, env=env, capture_output=True, text=True, timeout=300)
        output = run.stdout.rstrip("\n").split("\n") if run.stdout.strip() else []
        problem = None
        if run.returncode != 0:
            problem = f"exit {run.returncode}: {run.stderr.strip()}"
        elif expected is not None and len(output) != len(expected):
            problem = f"{len(output)} lines of output, {len(expected)} documented"
        elif exact and output != expected:
            problem = "the output differs from the one shown"
        elif expected is not None:
            for got, documented in zip(output, expected):
                if not same_shape(got, documented):
                    problem = f"output {got!r} does not have the shape of {documented!r}"
                    break
        if problem is None and span is not None and output != expected:
            replacements.append((span, output))
        status = "ok" if problem is None else f"FAILED: {problem}"
        print(f"{readme}:{line}: {status}")
        if problem:
            print("\n".join(output), file=sys.stderr)
            failures += 1
    if write and replacements:
        lines = text.split("\n")
        for (start, end), output in sorted(replacements, reverse=True):
            lines[start:end] = output
        with open(readme, "w", encoding="utf-8") as f:
            f.write("\n".join(lines))
        print(f"{readme}: {len(replacements)} output blocks rewritten")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
