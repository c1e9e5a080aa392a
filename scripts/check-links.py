#!/usr/bin/env python3
"""Checks the Markdown docs: relative links and anchors resolve, and no doc names a path of one machine.

Files: every *.md file git knows in ROOT (`git ls-files --cached --others --exclude-standard`, so
tracked files and new ones not yet committed, never build outputs or ignored files); outside a git
work tree, every *.md file under ROOT but hidden folders and build*/ folders.

Links: inline links and images `[text](target)`, `![alt](target)`, reference definitions
`[ref]: target`, and HTML `href="..."` / `src="..."`. A target with a scheme (http:, https:,
mailto:, ...) is not checked, nor is anything inside a fenced code block or an inline code span.
A relative target must name an existing file or folder inside ROOT (relative to the linking file;
a leading `/` is relative to ROOT, as on GitHub). An anchor (`path#anchor` or `#anchor`) into a
Markdown file must be one of its headings' GitHub slugs or an explicit `<a name|id="...">`:
the heading's text without Markdown markup, lowercased, every character that is not a letter,
digit, space, `-` or `_` dropped, spaces turned into `-`, and `-1`, `-2`, ... added to repeats.
An anchor into another kind of file is checked only if it is not a line anchor (`#L10`, `#L10-L20`).

Machine paths: an absolute path that exists only on the machine of whoever wrote it, so a reader
cannot follow it. Flagged anywhere in a doc, code included:
  - a home or project checkout: /home/..., /root, /Users/..., /work/..., /workspace/...,
    /mnt/..., /media/..., /scratch/..., and Windows' C:\\Users\\...;
  - a temporary name some program made up for one run: /tmp/tmp.XXXXXX and /tmp/tmpXXXXXXXX
    (mktemp, Python's tempfile), /tmp/pytest-of-..., /tmp/bash_jobs...
Flagged only in prose (outside code): any other /tmp/... path. In a command (a code block or an
inline code span) /tmp/NAME is a scratch path that the reader's own command creates, on any
machine; in a sentence it names a file that sits on the writer's machine (say "a scratch folder",
or put the result in the repository).
Not flagged: the system paths every Debian machine has with the same meaning (/usr/..., /etc/...,
/var/..., /opt/..., /dev/..., /proc/..., /sys/..., /run/..., /srv/..., /lib/..., /bin/...), URL
paths (`https://host/path`, `/status.json`), and relative paths such as ../shared/data.

Usage: scripts/check-links.py [ROOT]        check ROOT (default: the repository holding this script)
       scripts/check-links.py --self-test   check the checker on a tree made to break each rule
Exit status 1 with one line per problem, `file:line: broken link X (no such file | no anchor #y in Z)`
or `file:line: machine path P`; 0 when every doc is clean.
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
import unicodedata
import urllib.parse

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
HEADING = re.compile(r"^ {0,3}(#{1,6})[ \t]+(.*?)(?:[ \t]+#+)?[ \t]*$")
SETEXT = re.compile(r"^ {0,3}(=+|-+)[ \t]*$")
HTML_ANCHOR = re.compile(r"""<a\s[^>]*?(?:name|id)\s*=\s*["']([^"']+)["']""", re.I)
HTML_LINK = re.compile(r"""<(?:a|img)\s[^>]*?(?:href|src)\s*=\s*["']([^"']+)["']""", re.I)
REF_DEF = re.compile(r"^ {0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
LINE_ANCHOR = re.compile(r"^L\d+(?:C\d+)?(?:-L\d+(?:C\d+)?)?$")

# Paths of one machine, flagged anywhere (code included). The lookbehind keeps URL paths
# (host/home/...) and words such as frames/s/work out.
_START = r"(?<![\w.~/:-])"
MACHINE_ANYWHERE = re.compile(
    _START + r"(/(?:home|Users|work|workspace|mnt|media|scratch)/[^\s`'\")\]|,;]*"
    r"|/root(?:/[^\s`'\")\]|,;]*)?(?![\w.-])"
    r"|/tmp/(?:tmp\.?[A-Za-z0-9_]{6,}|pytest-of-|bash_jobs)[^\s`'\")\]|,;]*)"
    r"|(?<![\w])[A-Za-z]:\\\\?Users\\\\?[^\s`'\")\]|,;]*")
# Paths under /tmp, flagged only outside code.
MACHINE_IN_PROSE = re.compile(_START + r"(/tmp/[^\s`'\")\]|,;]*)")


def slug(heading_text):
    """GitHub's anchor for a heading's Markdown text."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading_text)  # links and images: their text
    text = re.sub(r"<[^>]+>", "", text)  # HTML tags
    text = text.replace("`", "").lower()
    out = []
    for ch in text:
        if ch in " -_" or ch.isalnum() or unicodedata.category(ch).startswith("M"):
            out.append("-" if ch == " " else ch)
    return "".join(out)


def strip_code_spans(line):
    """The line with every inline code span blanked (same length), and the spans' texts."""
    out, spans, i = [], [], 0
    while i < len(line):
        if line[i] == "`":
            n = len(line[i:]) - len(line[i:].lstrip("`"))
            ticks = "`" * n
            end = line.find(ticks, i + n)
            while end != -1 and end + n < len(line) and line[end + n] == "`":
                end = line.find(ticks, end + n + 1)
            if end != -1:
                spans.append(line[i + n:end])
                out.append(" " * (end + n - i))
                i = end + n
                continue
            out.append(ticks)
            i += n
            continue
        out.append(line[i])
        i += 1
    return "".join(out), spans


def inline_links(text):
    """Targets of [text](target) and ![alt](target) in a line with its code spans blanked."""
    targets = []
    for m in re.finditer(r"\]\(", text):
        if m.start() > 0 and text[m.start() - 1] == "\\":
            continue
        i = m.end()
        while i < len(text) and text[i] in " \t":
            i += 1
        if i < len(text) and text[i] == "<":
            end = text.find(">", i)
            if end != -1:
                targets.append(text[i + 1:end])
            continue
        depth, j = 0, i
        while j < len(text):
            c = text[j]
            if c == "\\":
                j += 2
                continue
            if c == "(":
                depth += 1
            elif c == ")":
                if depth == 0:
                    break
                depth -= 1
            elif c in " \t" and depth == 0:
                break  # a title follows
            j += 1
        if j <= len(text) and j > i:
            targets.append(text[i:j])
    return targets


class Doc:
    """One Markdown file: its prose lines (code blanked), its code, its anchors."""

    def __init__(self, path):
        with open(path, encoding="utf-8") as f:
            lines = f.read().split("\n")
        self.prose = []  # (line number, text with code blanked)
        self.code = []  # (line number, code text)
        self.anchors = set()
        counts = {}
        fence = None
        previous = ""
        for number, line in enumerate(lines, 1):
            m = FENCE.match(line)
            if fence:
                if m and m.group(1)[0] == fence[0] and len(m.group(1)) >= len(fence) and not line.strip(" `~"):
                    fence = None
                else:
                    self.code.append((number, line))
                continue
            if m:
                fence = m.group(1)
                continue
            text, spans = strip_code_spans(line)
            self.prose.append((number, text))
            for span in spans:
                self.code.append((number, span))
            heading = HEADING.match(line)
            title = heading.group(2) if heading else None
            if not heading and previous.strip() and SETEXT.match(line) and not previous.lstrip().startswith(("|", "-", "*")):
                title = previous.strip()
            if title is not None:
                base = slug(title)
                n = counts.get(base, 0)
                counts[base] = n + 1
                self.anchors.add(base if n == 0 else f"{base}-{n}")
            for a in HTML_ANCHOR.findall(line):
                self.anchors.add(a)
            previous = line

    def links(self):
        for number, text in self.prose:
            targets = inline_links(text) + HTML_LINK.findall(text)
            m = REF_DEF.match(text)
            if m:
                targets.append(m.group(1).strip("<>"))
            for target in targets:
                yield number, target


def doc_files(root):
    try:
        out = subprocess.run(
            ["git", "-C", root, "ls-files", "-z", "--cached", "--others", "--exclude-standard", "--", "*.md"],
            check=True, capture_output=True).stdout.decode()
        files = sorted({f for f in out.split("\0") if f})
    except (OSError, subprocess.CalledProcessError):
        files = []
        for dirpath, dirnames, names in os.walk(root):
            dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and not d.startswith("build"))
            files += [os.path.relpath(os.path.join(dirpath, n), root) for n in sorted(names) if n.endswith(".md")]
    return [f for f in files if os.path.isfile(os.path.join(root, f))]


def check(root):
    root = os.path.realpath(root)
    problems = []
    docs = {}
    counted = {"docs": 0, "links": 0}

    def doc(rel):
        if rel not in docs:
            docs[rel] = Doc(os.path.join(root, rel))
        return docs[rel]

    for rel in doc_files(root):
        d = doc(rel)
        counted["docs"] += 1
        for number, target in d.links():
            target = target.strip()
            if not target or SCHEME.match(target) or target.startswith("//"):
                continue
            counted["links"] += 1
            path, _, anchor = target.partition("#")
            path = urllib.parse.unquote(path.split("?", 1)[0])
            anchor = urllib.parse.unquote(anchor)
            if path:
                base = root if path.startswith("/") else os.path.dirname(os.path.join(root, rel))
                full = os.path.realpath(os.path.join(base, path.lstrip("/")))
                shown = os.path.relpath(full, root)
                if full != root and not full.startswith(root + os.sep):
                    problems.append(f"{rel}:{number}: broken link {target} (outside the repository: {shown})")
                    continue
                if not os.path.exists(full):
                    problems.append(f"{rel}:{number}: broken link {target} (no such file {shown})")
                    continue
            else:
                full, shown = os.path.join(root, rel), rel
            if not anchor or LINE_ANCHOR.match(anchor) or not full.endswith(".md") or not os.path.isfile(full):
                continue
            if anchor not in doc(os.path.relpath(full, root)).anchors and anchor.lower() not in doc(
                    os.path.relpath(full, root)).anchors:
                problems.append(f"{rel}:{number}: broken link {target} (no anchor #{anchor} in {shown})")
        for number, text in sorted(d.prose + d.code):
            for m in MACHINE_ANYWHERE.finditer(text):
                problems.append(f"{rel}:{number}: machine path {m.group(1).rstrip('.,:;')}")
        for number, text in d.prose:
            for m in MACHINE_IN_PROSE.finditer(text):
                if not MACHINE_ANYWHERE.match(text, m.start()):
                    problems.append(f"{rel}:{number}: machine path {m.group(1).rstrip('.,:;')} (a /tmp path in prose)")
    return sorted(set(problems), key=lambda p: (p.split(":")[0], int(p.split(":")[1]), p)), counted


def self_test(script):
    """Builds a tree with one broken file link, one broken anchor and machine paths, and requires the
    checker to name each of them and nothing else; then fixes them and requires a clean pass."""
    files = {
        "README.md": "# Top\n\nSee [the guide](docs/guide.md#set-up-the-camera-kinect-v1) and "
                     "[missing](docs/nothere.md).\nBad anchor: [x](docs/guide.md#no-such-heading).\n"
                     "Fine: [web](https://example.com/home/x), [mail](mailto:a@b.c), [self](#top), "
                     "![pic](docs/p.png), [dir](docs/), [code](src/a.cpp#L3-L9).\n"
                     "`[in code](nowhere.md)` and /usr/share/assimp, /dev/shm, /proc/cpuinfo, frames/s/work.\n",
        "docs/guide.md": "# Guide\n\n## Set up the camera (Kinect v1)\n\nBack to [top](../README.md#top); "
                         "[again](#set-up-the-camera-kinect-v1).\n\n```sh\n[not a link](gone.md)\n"
                         "build/bin/poseforest infer --out /tmp/parts.png\ncd /home/alice/poseforest\n```\n"
                         "The forest is in /tmp/poseforest-run/forest.pff.\n"
                         "Duplicates:\n\n## Step\n\n## Step\n\nSee [second](#step-1).\n",
        "docs/p.png": "",
        "src/a.cpp": "",
    }
    want = [
        "README.md:3: broken link docs/nothere.md (no such file docs/nothere.md)",
        "README.md:4: broken link docs/guide.md#no-such-heading (no anchor #no-such-heading in docs/guide.md)",
        "docs/guide.md:10: machine path /home/alice/poseforest",
        "docs/guide.md:12: machine path /tmp/poseforest-run/forest.pff (a /tmp path in prose)",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        for name, text in files.items():
            os.makedirs(os.path.dirname(os.path.join(tmp, name)), exist_ok=True)
            with open(os.path.join(tmp, name), "w", encoding="utf-8") as f:
                f.write(text)
        subprocess.run(["git", "init", "-q", tmp], check=False, capture_output=True)
        run = subprocess.run([sys.executable, script, tmp], capture_output=True, text=True)
        print(run.stdout + run.stderr, end="")
        got = [l for l in run.stdout.splitlines() if ": broken link " in l or ": machine path " in l]
        if run.returncode != 1:
            print(f"FAIL: exit {run.returncode} on a tree with broken links (want 1)")
            return 1
        if got != want:
            print("FAIL: want exactly these problems:\n  " + "\n  ".join(want))
            return 1
        fixed = files["README.md"].replace("docs/nothere.md", "docs/guide.md").replace(
            "#no-such-heading", "#guide")
        with open(os.path.join(tmp, "README.md"), "w", encoding="utf-8") as f:
            f.write(fixed)
        with open(os.path.join(tmp, "docs/guide.md"), "w", encoding="utf-8") as f:
            f.write(files["docs/guide.md"].replace("/home/alice/poseforest", "poseforest").replace(
                "/tmp/poseforest-run/forest.pff", "out/forest.pff"))
        run = subprocess.run([sys.executable, script, tmp], capture_output=True, text=True)
        if run.returncode != 0:
            print(run.stdout + run.stderr + "FAIL: the fixed tree was refused")
            return 1
    print("ok: a broken file link, a broken anchor and machine paths named; links in code, URLs, "
          "system paths and /tmp in commands pass; the fixed tree passes")
    return 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--self-test", action="store_true", help="check the checker on a broken tree")
    parser.add_argument("root", nargs="?", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    args = parser.parse_args()
    if args.self_test:
        return self_test(os.path.abspath(__file__))
    problems, counted = check(args.root)
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} problem(s) in the docs (scripts/check-links.py explains the rules)")
        return 1
    print(f"ok: {counted['links']} relative links in {counted['docs']} docs resolve; no machine paths")
    return 0


if __name__ == "__main__":
    sys.exit(main())
