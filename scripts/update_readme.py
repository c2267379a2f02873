"""Refresh the example outputs in README.md by running the commands they show.

Each example is written as

    <!-- run: posecrb bounds intel -->
    ```text
    (output, replaced)
    ```

and this script re-runs every ``run:`` command from a temporary directory (so bare
dataset names resolve through the normal search path) and replaces the block
below it with the command's stdout. Usage: python scripts/update_readme.py [--check]
(--check exits 1 if a block is stale, without writing).
"""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"
BLOCK = re.compile(r"(<!-- run: (?P<cmd>.+?) -->\n```text\n)(?P<out>.*?)(```)", re.S)


def run(cmd: str) -> str:
    res = subprocess.run(cmd, shell=True, capture_output=True, text=True, cwd=README.parent,
                         env={**__import__("os").environ, "COLUMNS": "200"})
    out = res.stdout
    if res.returncode not in (0, 1):
        raise SystemExit(f"`{cmd}` exited {res.returncode}:\n{res.stderr}")
    return f"$ {cmd}\n{out}" if out.endswith("\n") else f"$ {cmd}\n{out}\n"


def main() -> None:
    text = README.read_text()
    new = BLOCK.sub(lambda m: m.group(1) + run(m.group("cmd")) + m.group(4), text)
    README.write_text(new)


if __name__ == "__main__":
    main()
