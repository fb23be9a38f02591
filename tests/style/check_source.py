#!/usr/bin/env python3
"""The house rules a compiler does not check, over the project's own sources:

1. No function longer than 150 lines (from its signature to its closing brace, lambdas included);
   GridRegionGrowing::Detect, the detector's pipeline, under 80.
2. detection, registration and mapping include no evaluation or simulation header.
3. Code, headers, config files and the README describe the present: no dates, commit hashes or
   "before -> after" figures (the tests' comments may name data files and label mappings).

Usage: check_source.py SOURCE_DIR. Prints one line per problem; exit 1 when there is any."""
import pathlib
import re
import sys

MAX_LINES = 150
SHORT = {"GridRegionGrowing::Detect": 80}


def strip_comments_and_strings(text):
    """Blanks comments and literals (keeping newlines) so braces inside them do not count."""
    out, i, n = [], 0, len(text)
    while i < n:
        if text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        if text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append("\n" * text.count("\n", i, j))
            i = j
            continue
        raw = re.match(r'R"([^(\s]*)\(', text[i:i + 20]) if text[i] == "R" else None
        if raw and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            end = text.find(")" + raw.group(1) + '"', i)
            end = n if end < 0 else end + len(raw.group(1)) + 2
            out.append('""' + "\n" * text.count("\n", i, end))
            i = end
            continue
        c = text[i]
        if c in "\"'" and not (c == "'" and i > 0 and text[i - 1].isalnum()):
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            out.append(c + c)
            i = j + 1
            continue
        out.append(c)
        i += 1
    return "".join(out)


def functions(text):
    """(name, first line, last line) of every function body at namespace or class scope."""
    code = strip_comments_and_strings(text)
    stack, found, stmt_start = [], [], 0

    def line_of(pos):
        return code.count("\n", 0, pos) + 1

    for i, c in enumerate(code):
        if c == ";":
            stmt_start = i + 1
        elif c == "}":
            if stack:
                kind, start, name = stack.pop()
                if kind == "fn":
                    found.append((name, start, line_of(i)))
            stmt_start = i + 1
        elif c == "{":
            head = " ".join(code[stmt_start:i].split())
            if any(kind != "scope" for kind, _, _ in stack):
                kind = "block"
            elif re.search(r"\b(namespace|class|struct|union|enum)\b[^()]*$", head) or \
                    head.startswith("extern"):
                kind = "scope"
            elif ")" in head and not head.endswith("="):
                kind = "fn"
            else:
                kind = "block"
            name = re.search(r"([~\w:]+)\s*\(", head)
            lead = len(code[stmt_start:i]) - len(code[stmt_start:i].lstrip())
            stack.append((kind, line_of(stmt_start + lead), name.group(1) if name else head[:40]))
            stmt_start = i + 1
    return found


DATE = re.compile(r"\b20[0-9]{2}-[01][0-9]-[0-3][0-9]\b")
HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
ARROW = re.compile(r"[0-9][0-9.%]*\s*(?:[a-z%]+\s*)?->\s*[0-9]")


def prose_of(path, text):
    """The parts of a file that describe it: comments of code, comments of YAML, all of Markdown."""
    if path.suffix in (".md",):
        return text
    if path.suffix in (".yaml", ".yml", ".txt", ".cmake") or path.name in ("Makefile", "run"):
        return "\n".join(line.split("#", 1)[1] if "#" in line else "" for line in text.split("\n"))
    comments = []
    for m in re.finditer(r"//[^\n]*|/\*.*?\*/", text, re.S):
        comments.append((text.count("\n", 0, m.start()), m.group(0)))
    lines = [""] * (text.count("\n") + 1)
    for start, body in comments:
        for k, part in enumerate(body.split("\n")):
            lines[start + k] += part
    return "\n".join(lines)


def main():
    root = pathlib.Path(sys.argv[1]).resolve()
    problems = []
    code_dirs = ["apps", "datasets", "detection", "registration", "mapping", "tests", "examples"]
    sources = [p for d in code_dirs for p in (root / d).rglob("*") if p.suffix in (".cpp", ".hpp")]
    for path in sources:
        rel = path.relative_to(root)
        text = path.read_text(errors="replace")
        for name, first, last in functions(text):
            limit = SHORT.get(name, MAX_LINES)
            if last - first + 1 > limit:
                problems.append(f"{rel}:{first}: {name} is {last - first + 1} lines (at most {limit})")
    hidden = set()
    for lib in ("eval", "sim"):
        hidden |= {p.name for p in (root / "datasets" / lib / "include").rglob("*.hpp")}
    for module in ("detection", "registration", "mapping"):
        for path in (root / module).rglob("*"):
            if path.suffix not in (".cpp", ".hpp"):
                continue
            for n, line in enumerate(path.read_text(errors="replace").split("\n"), 1):
                m = re.match(r'\s*#include\s+"planeslam/datasets/([\w.]+)"', line)
                if m and m.group(1) in hidden:
                    problems.append(f"{path.relative_to(root)}:{n}: {module} includes "
                                    f"evaluation or simulation header {m.group(1)}")
    code = [p for p in sources if p.parts[len(root.parts)] != "tests"]
    prose_files = code + [root / "README.md"] + list((root / "config").glob("*.yaml")) + \
        [root / "CMakeLists.txt", root / "Makefile"] + list(root.glob("*/CMakeLists.txt"))
    for path in prose_files:
        if not path.exists():
            continue
        prose = prose_of(path, path.read_text(errors="replace"))
        for n, line in enumerate(prose.split("\n"), 1):
            for what, pattern in (("a date", DATE), ("a commit hash", HASH),
                                  ("a before -> after figure", ARROW)):
                m = pattern.search(line)
                if m:
                    problems.append(f"{path.relative_to(root)}:{n}: {what} ({m.group(0)!r}): "
                                    "history belongs in commit messages")
    for p in problems:
        print(p)
    print(f"check_source: {len(problems)} problem(s) in {len(sources)} source files")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
