"""Every command in README.md and docs/ runs as written, and the generated docs match the code.

The doc test copies the repository's files (``git ls-files``, from the working tree) into a scratch
folder, the state of a fresh clone, and runs the examples of every page in document order there
(README first, then docs/ by name), as a user would paste them:

- code blocks fenced as ``sh``/``bash``/``python`` or unlabelled, and indented blocks (4 spaces)
  whose lines start with a command; in a shell block, each line (``\\`` continues it) whose first
  word is ``humanoid-twin``, ``.venv/bin/...``, ``python``/``python3`` or ``VAR=value`` before
  one of these, run by bash in the scratch folder, ``.venv`` there being the interpreter's venv
  and ``.venv/bin`` first on ``PATH``; a trailing ``# ... exit N ...`` comment is the expected
  exit code (else 0). ``python`` blocks run as a script there.
- segments of a ``&&`` chain that create the venv, ``pip install`` or run the test suite are not
  run here: tests/project/test_install.py installs the package into a fresh venv, and the suite is this;
- ``humanoid-twin serve ...`` and ``view --web`` run until stopped: started, their first line
  read (the port or the URL), then stopped with SIGTERM (exit 143);
- markers, an HTML comment on the line before a block: ``<!-- not-run: REASON -->`` (a serial
  device, a display, a cluster, minutes of CPU: the commands are only parsed: the CLI's own
  parser for ``humanoid-twin``, ``--help`` for a script, ``compile`` for Python);
  ``<!-- test-args: ARGS -->`` (ARGS appended to each ``humanoid-twin run``/``sweep`` of the
  block, e.g. a shorter ``--duration``; the doc says so in its text); ``<!-- test-with: CMD -->``
  (a Python block that talks to a server: CMD, a ``serve``, is started first and the block's
  ``/dev/pts/N`` or ``socket://HOST:PORT`` is replaced by the port it prints).

Commands written inline in the prose, in backquotes (```humanoid-twin sweep stand --param ...```,
also across a line break), are checked without being run, with the CLI's own parser: a sentence
names a command and says what it does, often with placeholders, while the examples to run are the
blocks (a command worth running is written in a block). Each one parses as written, or the test
names its page and line: a missing required option, an unknown flag or command, a value its type
refuses. In them, an upper-case word is a placeholder (``SCENARIO``, ``FILE.rrd``, ``DEG``,
``SPEC`` ...: a sample value of its kind is put in its place, :data:`PLACEHOLDERS`), ``[`` ``]``
mark optional parts (parsed as given), ``a|b`` is ``a``, and ``...`` elides what the command
needs besides (an option's value: a sample; elsewhere: the command may lack its required
arguments). ``humanoid-twin run`` or ``humanoid-twin run/serve`` alone names commands (each must
exist); ``humanoid-twin serve: ...`` (the second word ending in a colon) quotes a message.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import REPO

DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
COMMAND = re.compile(r"^(?:[A-Z_]+=\S+\s+)*(?:\.venv/bin/\S+|humanoid-twin|python3?)(?:\s|$)")
MARKER = re.compile(r"<!--\s*(not-run|test-args|test-with):\s*(.*?)\s*-->")
SKIPPED = (re.compile(r"^python3? -m venv "), re.compile(r"pip install"), re.compile(r"-m pytest"))
PORT = re.compile(r"/dev/pts/\d+|socket://[\w.:\[\]]+:\d+")
VENV = Path(sys.executable).parent.parent


@dataclass
class Block:
    doc: Path
    line: int
    lang: str
    text: str
    marks: dict[str, str]

    @property
    def where(self) -> str:
        return f"{self.doc.relative_to(REPO)}:{self.line}"


def _marks(lines: list[str], i: int) -> dict[str, str]:
    """The markers on the lines right before line ``i`` (blank lines between are allowed)."""
    marks: dict[str, str] = {}
    j = i - 1
    while j >= 0 and (not lines[j].strip() or MARKER.search(lines[j])):
        for m in MARKER.finditer(lines[j]):
            marks[m.group(1)] = m.group(2)
        j -= 1
    return marks


def blocks(doc: Path) -> list[Block]:
    lines = doc.read_text(encoding="utf-8").splitlines()
    out: list[Block] = []
    i = 0
    while i < len(lines):
        fence = re.match(r"^(\s*)```(\w*)\s*$", lines[i])
        if fence:
            indent, lang = len(fence.group(1)), fence.group(2)
            j = i + 1
            while j < len(lines) and not lines[j].strip().startswith("```"):
                j += 1
            body = "\n".join(ln[indent:] for ln in lines[i + 1:j])
            if lang in ("", "sh", "bash", "python"):
                out.append(Block(doc, i + 1, lang or "sh", body, _marks(lines, i)))
            i = j + 1
            continue
        indented = lines[i].startswith("    ") and COMMAND.match(lines[i][4:])
        if indented and (i == 0 or not lines[i - 1].strip() or MARKER.search(lines[i - 1])):
            j = i
            while j < len(lines) and lines[j].startswith("    "):
                j += 1
            out.append(Block(doc, i + 1, "sh", "\n".join(ln[4:] for ln in lines[i:j]), _marks(lines, i)))
            i = j
            continue
        i += 1
    return out


def shell_commands(text: str) -> list[tuple[str, int]]:
    """(command, expected exit code) of each command line of a shell block."""
    joined = re.sub(r"\\\n\s*", " ", text)
    cmds = []
    for raw in joined.splitlines():
        line = re.sub(r"^\w+\$\s+", "", raw.strip())       # a prompt: "any$ humanoid-twin ..."
        if not COMMAND.match(line):
            continue
        code, _, comment = _split_comment(line)
        m = re.search(r"\bexit (\d+)", comment)
        for seg in code.split("&&"):
            seg = seg.strip()
            if seg and not any(p.search(seg) for p in SKIPPED):
                cmds.append((seg, int(m.group(1)) if m else 0))
    return cmds


def _split_comment(line: str) -> tuple[str, str, str]:
    """``code  # comment`` split at the first ``#`` outside quotes that follows a space."""
    quote = None
    for k, ch in enumerate(line):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and k and line[k - 1] == " ":
            return line[:k].rstrip(), "#", line[k + 1:]
    return line, "", ""


ALL_BLOCKS = [b for doc in DOCS for b in blocks(doc)]


def _argv(cmd: str) -> list[str]:
    words = shlex.split(cmd)
    while words and re.match(r"^[A-Z_]+=", words[0]):
        words = words[1:]
    return words


def _is_twin(argv: list[str]) -> bool:
    return bool(argv) and Path(argv[0]).name == "humanoid-twin"


def _runs_until_stopped(argv: list[str]) -> bool:
    return _is_twin(argv) and len(argv) > 1 and (argv[1] == "serve" or argv[1:3] == ["view", "--web"])


# -- the scratch clone ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def clone(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not (VENV / "bin" / "humanoid-twin").exists():
        pytest.skip(f"the docs' commands need the project installed in a venv ({VENV} has no humanoid-twin)")
    try:
        files = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: no list of the repository's files")
    dest = tmp_path_factory.mktemp("clone")
    for name in files.decode().split("\0"):
        src = REPO / name
        if name and src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name, follow_symlinks=False)
    # the compiled core, when built beside its source (an editable install builds it there)
    for so in (REPO / "humanoid_twin").rglob("*.so"):
        shutil.copy2(so, dest / so.relative_to(REPO))
    (dest / ".venv").symlink_to(VENV)
    return dest


def _env(clone: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{clone / '.venv' / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(clone)           # the clone's code, not the installed tree
    env["MPLBACKEND"] = "Agg"
    env.pop("PYTHONSTARTUP", None)
    return env


def _start(cmd: str, clone: Path) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(["bash", "-c", f"exec {cmd}"], cwd=clone, env=_env(clone), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    line = proc.stdout.readline().strip()
    return proc, line


def _stop(proc: subprocess.Popen) -> tuple[int, bool]:
    """SIGTERM, as a user's Ctrl-C or a supervisor: (exit code, whether a child it started was
    left running after it ended; such a child is killed here)."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        rc = proc.wait(30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        rc = proc.wait(10)
    time.sleep(0.5)
    try:
        os.killpg(proc.pid, signal.SIGKILL)      # its session: anything left is an orphan
        orphan = True
    except ProcessLookupError:
        orphan = False
    return rc, orphan


def _parse_only(cmd: str, clone: Path, where: str) -> None:
    argv = _argv(cmd)
    if _is_twin(argv):
        from humanoid_twin.cli.main import build_parser

        try:
            build_parser().parse_args(argv[1:])
        except SystemExit as exc:
            pytest.fail(f"{where}: `{cmd}` does not parse ({exc})")
    elif len(argv) > 1 and argv[1].startswith("scripts/"):
        r = subprocess.run([sys.executable, argv[1], "--help"], cwd=clone, env=_env(clone),
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, f"{where}: {argv[1]} --help: {r.stderr}"


# -- commands written inline in the prose --------------------------------------------------------
INLINE_CODE = re.compile(r"(?<!`)`([^`]+)`(?!`)")
INLINE_TWIN = re.compile(r"^(?:\.venv/bin/)?humanoid-twin(?:\s|$)")
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]*(?:\.[\w.]+)?$")
# a sample value per placeholder (the others: the word in lower case, which any path or name takes)
PLACEHOLDERS = {"SCENARIO": "stand", "DEG": "10", "S": "3", "N": "1", "F": "10", "X": "1",
                "SPEC": "silent:3@3.0", "PORT": "5000", "ADDR": "127.0.0.1:9876", "CH": "vcan0", "SCU": "1",
                "NODE": "0"}


@dataclass
class Inline:
    doc: Path
    line: int
    text: str

    @property
    def where(self) -> str:
        return f"{self.doc.relative_to(REPO)}:{self.line}"


def _prose(doc: Path) -> list[tuple[int, str]]:
    """``(first line number, text)`` of each paragraph of ``doc`` outside its code blocks and HTML
    comments (an inline code span may cross a line break, never a paragraph)."""
    lines = doc.read_text(encoding="utf-8").splitlines()
    fenced = set()
    for b in blocks(doc):
        n = b.text.count("\n") + 1
        first = b.line - (0 if lines[b.line - 1].strip().startswith("```") else 1)
        fenced.update(range(first - 1, first + n + 1))
    out, para, start = [], [], 0
    for i, ln in enumerate(lines + [""]):
        if i in fenced or not ln.strip() or ln.startswith("    ") and not para:
            if para:
                out.append((start + 1, re.sub(r"<!--.*?-->", "", "\n".join(para), flags=re.S)))
            para = []
            continue
        if not para:
            start = i
        para.append(ln)
    return out


def inline_commands(doc: Path) -> list[Inline]:
    """Every ``humanoid-twin ...`` written inline in ``doc``'s prose, whitespace made single."""
    found = []
    for line, text in _prose(doc):
        for m in INLINE_CODE.finditer(text):
            code = " ".join(m.group(1).split())
            if INLINE_TWIN.match(code):
                found.append(Inline(doc, line + text[:m.start()].count("\n"), code))
    return found


ALL_INLINE = [c for doc in DOCS for c in inline_commands(doc)]


def _sample_argv(text: str) -> tuple[list[str], bool]:
    """The words of an inline command with each placeholder given a sample value (module
    docstring); and whether ``...`` elided something the command may need."""
    bare = text.replace("[", " ").replace("]", " ")
    try:
        words = shlex.split(bare)[1:]
    except ValueError:                          # an unbalanced quote: the words as written
        words = bare.split()[1:]
    argv, elided = [], False
    for k, w in enumerate(words):
        w = w.split("|")[0] if "|" in w and w != "|" else w
        if w in ("|", ">", ">>", "2>", "2>&1", "&&", ";", "&"):
            break                               # the shell's from here (a pipe, a redirection), or
                                                # alternatives of a whole tail: the first one
        if w.endswith("..."):
            elided = True
            w = w[:-3]
            if not w:
                if argv and argv[-1].startswith("-") and "=" not in argv[-1] and k == len(argv):
                    argv.append("x")            # an option's value
                continue
        if PLACEHOLDER.match(w):
            stem, dot, ext = w.partition(".")
            w = PLACEHOLDERS.get(stem, stem.lower()) + dot + ext
        elif "=" in w and not w.startswith("-"):
            name, _, value = w.partition("=")
            w = f"{name}={PLACEHOLDERS.get(value, value)}"
        argv.append(w)
    return argv, elided


def check_inline(cmd: Inline) -> str | None:
    """Why the inline command ``cmd`` does not parse with the CLI's parser, or None when it does
    (or when it names commands, or quotes a message: module docstring)."""
    import argparse
    import contextlib
    import io

    from humanoid_twin.cli.main import build_parser

    parser = build_parser()
    words = cmd.text.split()
    if len(words) > 1 and words[1].endswith(":"):
        return None                             # a message the CLI prints: `humanoid-twin serve: wrote F`
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    if len(words) == 1:
        return None                             # the program's name
    if len(words) == 2 and not words[1].startswith("-"):
        unknown = [w for w in words[1].split("/") if w not in sub.choices]
        return f"no such command {' '.join(unknown)}" if unknown else None
    argv, elided = _sample_argv(cmd.text)
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            # as the CLI's main: sweep gives the options it does not know to every run (checked
            # as run's, cli/sweep.py)
            args, extra = parser.parse_known_args(argv)
            if extra and args.command == "sweep":
                parser.parse_args(["run", "stand", *extra])
            elif extra:
                parser.error(f"unrecognized arguments: {' '.join(extra)}")
    except SystemExit as exc:
        message = err.getvalue().strip()
        if exc.code == 0 or (elided and "arguments are required" in message):
            return None
        return f"`{' '.join(argv)}`: {message or exc}"
    return None


def test_every_inline_command_of_the_docs_parses() -> None:
    assert len(ALL_INLINE) >= 20, [c.text for c in ALL_INLINE]
    failures = [f"{c.where}: `{c.text}`: {why}" for c in ALL_INLINE if (why := check_inline(c))]
    assert not failures, "\n".join(failures)


def test_the_inline_check_finds_what_fails() -> None:
    where = Inline(REPO / "README.md", 1, "")
    bad = {"humanoid-twin sweep stand --param pic-mhz=2,5,10,40": "--out",        # required
           "humanoid-twin run stand --tilt abc": "--tilt",                         # its type refuses it
           "humanoid-twin run SCENARIO --no-such-flag": "unrecognized",
           "humanoid-twin run/frobnicate": "frobnicate",
           "humanoid-twin view --web": "file"}
    for text, why in bad.items():
        where.text = text
        assert why in (check_inline(where) or ""), text
    good = ("humanoid-twin run SCENARIO --fault SPEC [--fault SPEC ...]", "humanoid-twin serve --law ...",
            "humanoid-twin run ... --out FILE.rrd --can-log FILE.asc", "humanoid-twin serve: wrote x.serial",
            "humanoid-twin --version", "humanoid-twin run/serve/view/sweep",
            "humanoid-twin sweep stand --param pic-mhz=2,5 --out FILE.csv",
            "humanoid-twin run stand --json | jq .fell", "humanoid-twin run stand --no-record > out.txt",
            "humanoid-twin sweep stand --param 'tilt=0,10' --out t.csv")
    for text in good:
        where.text = text
        assert check_inline(where) is None, (text, check_inline(where))
    # found in the prose across a line break, not in code blocks nor comments
    doc = REPO / "README.md"
    spans = [c.text for c in inline_commands(doc)]
    assert "humanoid-twin run --help" in spans, spans
    assert not any("flexao --out flexao.rrd" in t for t in spans)


def _run_shell(block: Block, clone: Path, ran: set[tuple[str, int]]) -> None:
    """Run the block's commands in the clone, each as written; ``ran``: the commands already run
    there (a page that repeats the README's example, ``.venv/bin/humanoid-twin X`` or
    ``humanoid-twin X``, runs it once: the same program on the same files)."""
    extra = block.marks.get("test-args", "")
    for cmd, want in shell_commands(block.text):
        if "not-run" in block.marks:
            _parse_only(cmd, clone, block.where)
            continue
        argv = _argv(cmd)
        if extra and _is_twin(argv) and argv[1] in ("run", "sweep"):
            cmd = f"{cmd} {extra}"
        key = (re.sub(r"(^|\s)\.venv/bin/humanoid-twin\b", r"\1humanoid-twin", cmd), want)
        if key in ran:
            continue
        ran.add(key)
        if _runs_until_stopped(argv):
            proc, line = _start(cmd, clone)
            rc, orphan = _stop(proc)
            err = proc.stderr.read()
            assert not orphan, f"{block.where}: `{cmd}` left a process running after SIGTERM: {err}"
            assert re.search(r"^/dev/pts/\d+$|^socket://|http://127\.0\.0\.1:\d+/", line), \
                f"{block.where}: `{cmd}` printed {line!r} first; stderr: {err}"
            assert rc == 143, f"{block.where}: `{cmd}` exit {rc} after SIGTERM; stderr: {err}"
            continue
        r = subprocess.run(["bash", "-c", cmd], cwd=clone, env=_env(clone), capture_output=True,
                           text=True, timeout=300)
        assert r.returncode == want, \
            f"{block.where}: `{cmd}` exit {r.returncode}, want {want}: {r.stderr[-2000:]}"


def _run_python(block: Block, clone: Path) -> None:
    if "not-run" in block.marks:
        compile(block.text, block.where, "exec")
        return
    text, server = block.text, None
    if "test-with" in block.marks:
        server, port = _start(block.marks["test-with"], clone)
        assert PORT.fullmatch(port), f"{block.where}: the server printed {port!r}"
        text = PORT.sub(port, text)
    script = clone / f"_doc_block_{block.doc.stem}_{block.line}.py"
    script.write_text(text + "\n")
    try:
        r = subprocess.run([sys.executable, script.name], cwd=clone, env=_env(clone), capture_output=True,
                           text=True, timeout=300)
    finally:
        if server is not None:
            assert _stop(server) == (143, False)
    assert r.returncode == 0, f"{block.where}: exit {r.returncode}: {r.stderr[-2000:]}"


@pytest.mark.slow
def test_every_command_of_the_docs_runs_as_written(clone: Path) -> None:
    t0 = time.perf_counter()
    took = []
    ran: set[tuple[str, int]] = set()
    for block in ALL_BLOCKS:
        t1 = time.perf_counter()
        if block.lang == "python":
            _run_python(block, clone)
        else:
            _run_shell(block, clone, ran)
        took.append((time.perf_counter() - t1, block.where))
    slowest = ", ".join(f"{w} {s:.0f} s" for s, w in sorted(took, reverse=True)[:12])
    print(f"{len(ALL_BLOCKS)} blocks in {time.perf_counter() - t0:.0f} s; slowest: {slowest}")


def test_the_doc_blocks_are_found_and_the_not_run_list_is_short() -> None:
    runnable = [b for b in ALL_BLOCKS if shell_commands(b.text) or b.lang == "python"]
    assert len(runnable) >= 20
    not_run = [b for b in runnable if "not-run" in b.marks]
    for b in not_run:
        assert b.marks["not-run"], f"{b.where}: a not-run marker says why"
    assert len(not_run) <= 8, [b.where for b in not_run]
    # every marker written in the docs belongs to a block found here (none silently ignored)
    written = sum(len(MARKER.findall(doc.read_text(encoding="utf-8"))) for doc in DOCS)
    assert written == sum(len(b.marks) for b in ALL_BLOCKS)
    # the README's quick start is found, its install steps left to tests/project/test_install.py
    first = shell_commands(ALL_BLOCKS[0].text)
    assert first == [(".venv/bin/humanoid-twin run flexao --out flexao.rrd", 0)]
    assert shell_commands("a  # x\n.venv/bin/humanoid-twin run x --json   # exit 3: safe\n") == [
        (".venv/bin/humanoid-twin run x --json", 3)]


# -- docs/fault_matrix.md: generated by scripts/fault_matrix.py (48 runs, minutes: too long for a
# test). Checked here: the page's text and its list of cells are the script's (a fault kind or a
# scenario added to the script fails until the page is regenerated), a sample of rows re-run now
# gives the same text, and every latency in it is within what docs/supervisor.md states.
MATRIX = REPO / "docs" / "fault_matrix.md"
SAMPLE = (("stand", "silent:3@3.0"), ("stand", "bus-off:0@3.0"), ("stand", "deadline:4@3.0"),
          ("levantar_perna", "deadline:4@3.0"), ("flexao", None))


def _fault_matrix():  # noqa: ANN202
    import importlib.util

    spec = importlib.util.spec_from_file_location("fault_matrix", REPO / "scripts" / "fault_matrix.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _matrix_page() -> tuple[list[str], list[str]]:
    lines = MATRIX.read_text(encoding="utf-8").splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("|---"))
    return lines[:k + 1], lines[k + 1:]


def test_the_fault_matrix_page_is_the_scripts_text_and_cells() -> None:
    fm = _fault_matrix()
    head, rows = _matrix_page()
    wall = int(re.search(r"runs, (\d+) s wall\)", head[2]).group(1))
    regenerate = "regenerate it: python scripts/fault_matrix.py --seed 0 --out docs/fault_matrix.md"
    assert head == fm.header(0, len(fm.jobs(0)), wall), regenerate
    cells = [(r.split("|")[2].strip(), r.split("|")[1].strip().strip("`")) for r in rows]
    assert cells == [(sc, spec or "(none)") for sc, spec, _ in fm.jobs(0)], regenerate


@pytest.mark.parametrize(("scenario", "spec"), SAMPLE)
def test_a_row_of_the_fault_matrix_is_what_the_code_gives_now(scenario: str, spec: str | None) -> None:
    fm = _fault_matrix()
    _, rows = _matrix_page()
    line = fm.row_line(fm.cell((scenario, spec, 0)))
    assert line in rows, f"docs/fault_matrix.md is stale: now {line}"


def _stated_latency_ms(rule: str) -> tuple[float, float]:
    """The latency range docs/supervisor.md's rule table states for ``rule`` (``A-B ms`` or ``≤ B ms``)."""
    for ln in (REPO / "docs" / "supervisor.md").read_text(encoding="utf-8").splitlines():
        cols = [c.strip() for c in ln.split("|")]
        if len(cols) > 6 and cols[2] == f"`{rule}`" and cols[3] in ("0", "1-8"):
            m = re.match(r"(?:(\d+)-(\d+)|≤ (\d+)) ms", cols[6])
            if m:
                return (float(m.group(1)), float(m.group(2))) if m.group(1) else (0.0, float(m.group(3)))
    raise AssertionError(f"docs/supervisor.md states no latency for {rule}")


def test_every_latency_of_the_fault_matrix_is_within_the_supervisor_docs_range() -> None:
    # the faults whose rule fires on the fault itself (a corrupted bus takes a while to go
    # bus-off; a Slave's bus-off is reported with its next packet): the latency from T0
    _, rows = _matrix_page()
    checked = 0
    for r in rows:
        cols = [c.strip() for c in r.split("|")]
        spec, detected, lat = cols[1].strip("`"), cols[3], cols[4]
        kind = spec.split(":")[0]
        rule = {"silent": "silent", "deadline": "deadline", "bus-off": "bus_off"}.get(kind)
        if rule is None or not detected.startswith(rule):
            continue
        lo, hi = _stated_latency_ms(rule)
        assert lo <= int(lat) <= hi, f"{r}: docs/supervisor.md says {rule} within {lo:g}-{hi:g} ms"
        checked += 1
    assert checked >= 12
    # the deadline rule's hold, as the doc words it, is the supervisor's setting
    from humanoid_twin.hardware import PWM_PERIOD_US
    from humanoid_twin.master.supervisor import SupervisorConfig

    ticks = SupervisorConfig().deadline_ticks
    hold_ms = (ticks - 1) * PWM_PERIOD_US // 1000
    assert f"for {ticks} ticks ({hold_ms} ms between the first and the last)" in \
        (REPO / "docs" / "supervisor.md").read_text(encoding="utf-8")
