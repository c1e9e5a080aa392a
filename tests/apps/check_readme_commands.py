#!/usr/bin/env python3
"""The README's command table is `poseforest help --markdown` (apps/commands/commands.cpp):
fails naming the first line that differs. Usage: check_readme_commands.py POSEFOREST README.md"""
import subprocess
import sys

BEGIN = "<!-- commands: `poseforest help --markdown` prints this table; tests/apps checks it -->"
END = "<!-- end of commands -->"


def main() -> int:
    program, readme = sys.argv[1], sys.argv[2]
    generated = subprocess.run([program, "help", "--markdown"], check=True, capture_output=True,
                               text=True).stdout.splitlines()
    text = open(readme, encoding="utf-8").read()
    if BEGIN not in text or END not in text:
        print(f"{readme}: no command table between\n  {BEGIN}\nand\n  {END}")
        return 1
    table = text.split(BEGIN, 1)[1].split(END, 1)[0].strip("\n").splitlines()
    if table == generated:
        print(f"{readme}: the command table matches `poseforest help --markdown` ({len(generated)} lines)")
        return 0
    for i, (a, b) in enumerate(zip(table + [""] * len(generated), generated + [""] * len(table))):
        if a != b:
            print(f"{readme}: command table line {i + 1} differs from `poseforest help --markdown`:\n"
                  f"  README:    {a}\n  generated: {b}\n"
                  "(paste the output of `poseforest help --markdown` between the markers)")
            break
    return 1


if __name__ == "__main__":
    sys.exit(main())
