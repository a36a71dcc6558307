"""The measuring stick of the redesign issue (issue 49, "One owner per stage"): its countable targets, counted
on the tree with Python's ``ast``, every counted site listed so that a reader can check it.

What is counted, and how (each function takes the repository's root; ``mifaces/`` is the package,
``plugins/`` is not scanned):

1. **Branches on a light's kind** (``light_branches``), in every module of ``mifaces/`` but the packages
   ``mifaces/lights/`` and ``mifaces/light_estimation/`` (where they will belong). A *site* is one test: the
   test of an ``if`` or ``elif`` (each ``elif`` its own site), of a ternary, a ``while``, an ``assert``, a
   comprehension's ``if``, a ``match``'s subject or a ``case``'s guard; and an ``and``/``or`` expression
   that is in no such test (``directional = environment or lights[0].directional``). A site counts when its
   test (a nested ternary's or comprehension's test being a site of its own) *reads a light's kind*, once
   however many reads it holds:

   - the attribute ``unknown``, ``relative``, ``estimated``, ``kind``, ``environment``, ``directional`` or
     ``spheres`` of a light (read, not assigned);
   - the attribute ``position``, ``direction``, ``envmap`` or ``guess`` of a light compared with ``None``
     (``is``, ``is not``, ``==``, ``!=``);
   - ``isinstance(x, C)`` with ``C`` (or one of a tuple) a light class: ``Light`` and every class defined
     in ``mifaces/lights/``.

   *Of a light* is a name heuristic: the object's source text contains ``light`` (any case:
   ``light``, ``lights[0]``, ``capture.light(name)``), or it is a name the enclosing function (or module)
   binds to a light: the loop variable of a ``for`` or comprehension over something whose text contains
   ``light`` (through ``enumerate``, ``zip``, ``.items()`` and ``.values()``: ``for key, source in
   lights.items()``), a name assigned a call of a function whose name ends in ``light``
   (``lamp = capture.light(...)``, ``fitted_light(...)``), an element ``...lights[...]``, ``next(...)`` of
   something whose text contains ``lights``, or an attribute named ``light``/``*_light``; and a parameter
   annotated with a light class. ``self`` inside ``Light``'s
   own methods is not a light here (the class that owns its fields may read them).
   Beside them, **``replace`` of a light** (``light_replaces``): calls of ``replace(x, ...)`` or
   ``dataclasses.replace(x, ...)`` whose first argument is a light by the same rule.
2. **Loose modules** (``loose_modules``): the ``.py`` files directly in ``mifaces/`` but ``__init__.py``.
3. **Parameters** (``parameter_counts``): every ``def`` in ``mifaces/`` (methods and nested functions
   included, lambdas not), its parameters counted one each whether positional-only, positional,
   keyword-only, ``*args`` or ``**kwargs``, a method's first ``self``/``cls`` left out. *Public*: a
   function at a module's top level or a method of a class at a module's top level (classes nested in
   public classes too), its name, its classes' names and every part of its module's path
   (``__init__.py`` standing for its package) without a leading ``_``; so ``__init__`` methods are not
   public. Reported: those with 15 or more parameters, the public ones with more than 10, and how many
   functions have each count.
4. **Module length** (``long_modules``): modules of ``mifaces/`` of more than 450 lines (``splitlines``).
5. **fit_brdf** (``fit_brdf_size``): the ``def fit_brdf`` at the top level of a module of
   ``mifaces/reflectance/``, its length from its first decorator (or ``def``) to its last line, and its
   calls of ``fit_brdf`` by name within itself (direct recursion).
6. **CLI flags declared more than once** (``duplicate_flags``): the calls ``click.option(...)`` (or
   ``option(...)`` imported from ``click``) in ``mifaces/``, grouped by the flag's long name: the first
   ``--name`` of its declarations, ``--x/--no-x`` read as ``--x``. A flag declared in more than one place
   counts; of those, *copies* are the flags declared more than once with the same ``default=``
   expression, not a literal (one option of the API copied, e.g. ``default(FitOptions, "resolution")``;
   a flag copied with two defaults counts once per default). A flag whose name is built at run time (an
   f-string, a variable) is listed apart (``dynamic_flags``), not grouped.
7. **Name checks in export** (``export_name_checks``): in ``mifaces/export/``, each comparison
   (``==``, ``!=``, ``in``, ``not in``) of an expression with a string literal (or a tuple, list or set of
   them) where the literal is the ``name`` of a BRDF model class of ``mifaces/brdf/`` or the expression
   names a model: its last name (variable, attribute or string subscript) is ``name``, ``model``,
   ``model_name``, ``brdf``, ``brdf_model`` or ``brdf_name``.
8. **``sys.path.insert`` in validation/** (``sys_path_inserts``): the scripts ``validation/*.py`` that call
   ``sys.path.insert``.
9. **Reads back in the pipeline** (``pipeline_reads``): in ``mifaces/pipeline.py`` or
   ``mifaces/pipeline/``, the calls of a function of ``mifaces`` (imported from it, or defined in the
   module) that reads a folder, whose name, a leading ``_`` aside, starts with ``load_`` or ``read_`` or is
   one of :data:`FOLDER_READERS` (``export_face`` reads a BRDF result folder), **with an argument built
   from the pipeline's own output folder** (an expression that names ``out``; of a folder reader, its
   first argument, the folder it reads: ``export_face(estimate, out / "face.glb")`` writes there and reads
   nothing): a result read back from where the pipeline wrote it. Reads of its inputs (``load_capture(capture)``, the ground truth) are not
   counted; every ``load_*``/``read_*`` call is still listed apart (``pipeline_calls``).

Targets (``TARGETS``, each saying where it comes from): issue 49's "Done when" gives no branch on a
light's kind outside its two packages, at most 2 loose modules, no function of 15 or more parameters,
no public one of more than 10, no module over 450 lines, ``fit_brdf`` at most 40 lines and not calling
itself, a CLI flag declared once (the copies: one option declared on several commands), no name checks
in export, no read-back in the pipeline; its "What to build" asks for ``validation/`` without
``sys.path.insert``. The ``replace()`` count has no target of the issue's. The issue's own counts when it was written are
``ISSUE``. The counting is standard library only; ``provenance`` writes the file.

Run:  python validation/design_metrics.py [--root DIR] [--out FILE]
Writes validation/results/design_metrics.json (a few seconds).
"""

from __future__ import annotations

import argparse
import ast
import functools
import sys
from collections import Counter
from pathlib import Path

from provenance import write_result

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "mifaces"
EXCLUDED = ("mifaces/lights", "mifaces/light_estimation")  # where the light's kind will be read
KIND_FLAGS = frozenset({"unknown", "relative", "estimated", "kind", "environment", "directional", "spheres"})
KIND_NONE = frozenset({"position", "direction", "envmap", "guess"})
MAX_PARAMETERS, MAX_PUBLIC_PARAMETERS, MAX_LINES = 15, 10, 450
MODEL_NAMES = frozenset({"name", "model", "model_name", "brdf", "brdf_model", "brdf_name"})
PIPELINE = ("mifaces/pipeline.py", "mifaces/pipeline")

#: The issue's counts when it was written (as its text gives them).
ISSUE = {"light_branches": 63, "light_branch_files": 16, "light_replaces": 12, "loose_modules": 25,
         "functions_15_parameters": 6, "public_over_10_parameters": 21}
_PROPOSED = "proposed here, not the issue's"
_DONE = "issue 49, done when"
#: Functions that read a result folder without ``load_``/``read_`` in their names: the folder is their
#: first argument (``export_face`` also takes the estimate in memory, and its second is the file it writes).
FOLDER_READERS = frozenset({"export_face"})

TARGETS = {
    "light_branches": (0, _DONE),
    "light_replaces": (0, f"{_PROPOSED}: a light answers for itself"),
    "loose_modules": (2, _DONE),
    "functions_15_parameters": (0, _DONE),
    "public_over_10_parameters": (0, _DONE),
    "long_modules": (0, _DONE),
    "fit_brdf_lines": (40, _DONE),
    "fit_brdf_calls_itself": (False, _DONE),
    "duplicate_flags": (None, "none: different commands' --out or --force are different flags"),
    "copied_flags": (0, f"{_DONE}: a CLI flag is declared once"),
    "export_name_checks": (0, _DONE),
    "sys_path_inserts": (0, "issue 49, what to build"),
    "pipeline_reads": (0, f"{_DONE}: pipeline/ never reads back a result folder that it wrote"),
}


# ------------------------------------------------------------------------------------------- the tree

@functools.lru_cache(maxsize=None)
def _parsed(path: str, mtime_ns: int, size: int) -> tuple[str, ast.Module]:
    source = Path(path).read_text(encoding="utf-8")
    return source, ast.parse(source, path)


def parse(path: Path) -> tuple[str, ast.Module]:
    """A file's source and syntax tree (cached while the file is unchanged)."""
    stat = path.stat()
    return _parsed(str(path), stat.st_mtime_ns, stat.st_size)


def modules(root: Path, under: str = PACKAGE) -> list[tuple[str, Path]]:
    """The ``.py`` files under ``root/under`` (sorted), each with its root-relative POSIX path."""
    root = Path(root)
    base = root / under
    if base.is_file():
        return [(under, base)]
    # (``mifaces/plugins``: where the installed package and reproduce.py's scratch copy put ``plugins/``)
    return [(p.relative_to(root).as_posix(), p) for p in sorted(base.rglob("*.py"))
            if "__pycache__" not in p.parts and not p.relative_to(root).as_posix().startswith("mifaces/plugins/")]


def _excluded(rel: str) -> bool:
    return any(rel == e or rel.startswith(e + "/") for e in EXCLUDED)


def _text(node: ast.AST) -> str:
    return ast.unparse(node)


def _dotted(node: ast.AST) -> str | None:
    """``a.b.c`` of a name or a chain of attributes of a name (None for anything else), without unparsing."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return None if base is None else f"{base}.{node.attr}"
    return None


@functools.lru_cache(maxsize=64)
def _lines(source: str) -> list[bytes]:
    return [line.encode() for line in source.splitlines()]


def _segment(source: str, node: ast.AST) -> str:
    """The node's source text, on one line (``ast.get_source_segment``, without splitting the file each time)."""
    lines = _lines(source)[node.lineno - 1:node.end_lineno]
    if not lines or node.end_col_offset is None:
        return _text(node)
    if len(lines) == 1:
        text = lines[0][node.col_offset:node.end_col_offset]
    else:
        text = b"\n".join([lines[0][node.col_offset:], *lines[1:-1], lines[-1][:node.end_col_offset]])
    return " ".join(text.decode().split())


def _last_name(node: ast.AST) -> str | None:
    """The last name of an expression: a variable's, an attribute's, a string subscript's key, a call's callee's."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant) and isinstance(node.slice.value, str):
        return node.slice.value
    if isinstance(node, ast.Call):
        return _last_name(node.func)
    return None


# -------------------------------------------------------------------------------- 1. the light's kind

def light_classes(root: Path) -> set[str]:
    """``Light`` and the classes defined in ``mifaces/lights/``."""
    names = {"Light"}
    if (Path(root) / PACKAGE / "lights").is_dir():
        for _, path in modules(root, f"{PACKAGE}/lights"):
            names |= {n.name for n in ast.walk(parse(path)[1]) if isinstance(n, ast.ClassDef)}
    return names


def _names_class(node: ast.AST | None, classes: set[str]) -> bool:
    """Whether a type expression (an annotation, ``isinstance``'s second argument) names a light class."""
    if node is None:
        return False
    for n in ast.walk(node):
        if isinstance(n, ast.Name) and n.id in classes or isinstance(n, ast.Attribute) and n.attr in classes:
            return True
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and any(
                c in n.value.replace("|", " ").replace("[", " ").replace("]", " ").split() for c in classes):
            return True
    return False


def _mentions_light(node: ast.AST) -> bool:
    return "light" in _text(node).lower()


def _element_names(target: ast.AST, iterable: ast.AST) -> set[str]:
    """The names ``for target in iterable`` binds to lights."""
    if isinstance(iterable, ast.Call) and isinstance(target, (ast.Tuple, ast.List)):
        func = iterable.func
        if isinstance(func, ast.Name) and func.id == "enumerate" and iterable.args and len(target.elts) == 2:
            return _element_names(target.elts[1], iterable.args[0])
        if isinstance(func, ast.Name) and func.id == "zip" and len(target.elts) == len(iterable.args):
            return set().union(*(_element_names(t, a) for t, a in zip(target.elts, iterable.args)))
        if isinstance(func, ast.Attribute) and func.attr == "items" and len(target.elts) == 2:
            return _element_names(target.elts[1], func.value)
    if isinstance(iterable, ast.Call) and isinstance(iterable.func, ast.Attribute) and iterable.func.attr == "values":
        return _element_names(target, iterable.func.value)
    if isinstance(target, ast.Name) and _mentions_light(iterable):
        return {target.id}
    return set()


def _yields_light(value: ast.AST) -> bool:
    """Whether an assigned value is taken for a light (see the module docstring)."""
    if isinstance(value, ast.IfExp):
        return _yields_light(value.body) or _yields_light(value.orelse)
    if isinstance(value, ast.Call):
        name = _last_name(value.func) or ""
        if name == "next" and value.args:
            return "lights" in _text(value.args[0]).lower()
        return name.lower().endswith("light")
    if isinstance(value, ast.Subscript):
        return "lights" in _text(value.value).lower()
    if isinstance(value, ast.Attribute):
        return value.attr == "light" or value.attr.endswith("_light")
    return False


def _bound_lights(scope: ast.AST, classes: set[str]) -> set[str]:
    """The names a function (or module) binds to lights, nested functions and classes left out."""
    names: set[str] = set()
    if isinstance(scope, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
        a = scope.args
        for arg in [*a.posonlyargs, *a.args, *a.kwonlyargs]:
            if _names_class(arg.annotation, classes):
                names.add(arg.arg)
    todo = list(scope.body) if isinstance(scope.body, list) else [scope.body]
    while todo:
        node = todo.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue
        if isinstance(node, (ast.For, ast.AsyncFor, ast.comprehension)):
            names |= _element_names(node.target, node.iter)
        elif isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            if _yields_light(node.value):
                names.add(node.targets[0].id)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            if _names_class(node.annotation, classes) or node.value is not None and _yields_light(node.value):
                names.add(node.target.id)
        elif isinstance(node, ast.NamedExpr) and _yields_light(node.value):
            names.add(node.target.id)
        todo.extend(ast.iter_child_nodes(node))
    return names


#: (node type, field) -> the kind of test that field holds (an ``if``'s own test: "if" or "elif").
TESTS = {(ast.If, "test"): "if", (ast.While, "test"): "while", (ast.IfExp, "test"): "ternary",
         (ast.comprehension, "ifs"): "comprehension if", (ast.Assert, "test"): "assert",
         (ast.Match, "subject"): "match", (ast.match_case, "guard"): "case guard"}


def _test_kind(parent: ast.AST, field: str) -> str | None:
    """What kind of test ``parent``'s ``field`` holds (None: not a test)."""
    return TESTS.get((type(parent), field))


class _Sites:
    """Walks one module, collecting the branch sites on a light's kind and the ``replace`` calls of lights."""

    def __init__(self, rel: str, source: str, classes: set[str]):
        self.rel, self.source, self.classes = rel, source, classes
        self.sites: list[dict] = []
        self.replaces: list[dict] = []
        self.elifs: set[int] = set()

    def lightish(self, node: ast.AST, names: frozenset[str]) -> bool:
        return _mentions_light(node) or isinstance(node, ast.Name) and node.id in names

    def read(self, node: ast.AST, names: frozenset[str]) -> str | None:
        """What kind-read ``node`` is (None: none)."""
        if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Load) and node.attr in KIND_FLAGS \
                and self.lightish(node.value, names):
            return f".{node.attr}"
        if isinstance(node, ast.Compare) and len(node.ops) == 1 \
                and isinstance(node.ops[0], (ast.Is, ast.IsNot, ast.Eq, ast.NotEq)):
            for side, other in ((node.left, node.comparators[0]), (node.comparators[0], node.left)):
                if isinstance(side, ast.Attribute) and side.attr in KIND_NONE and isinstance(other, ast.Constant) \
                        and other.value is None and self.lightish(side.value, names):
                    return f".{side.attr} is None"
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "isinstance" \
                and len(node.args) == 2 and _names_class(node.args[1], self.classes):
            return "isinstance"
        return None

    def site(self, kind: str, test: ast.AST) -> dict:
        record = {"file": self.rel, "line": test.lineno, "kind": kind, "test": test, "reads": set()}
        self.sites.append(record)
        return record

    def visit(self, node: ast.AST, site: dict | None, names: frozenset[str]) -> None:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            names = names | _bound_lights(node, self.classes)
        if isinstance(node, ast.If) and isinstance(node.orelse, list) and len(node.orelse) == 1 \
                and isinstance(node.orelse[0], ast.If) and node.orelse[0].col_offset == node.col_offset:
            self.elifs.add(id(node.orelse[0]))
        if site is None and isinstance(node, ast.BoolOp):
            site = self.site("boolean operand", node)
        if site is not None:
            what = self.read(node, names)
            if what:
                site["reads"].add(what)
        if isinstance(node, ast.Call) and node.args and (
                isinstance(node.func, ast.Name) and node.func.id == "replace"
                or isinstance(node.func, ast.Attribute) and node.func.attr == "replace"
                and isinstance(node.func.value, ast.Name) and node.func.value.id == "dataclasses") \
                and self.lightish(node.args[0], names):
            self.replaces.append({"file": self.rel, "line": node.lineno, "call": _segment(self.source, node)[:160]})
        for field, value in ast.iter_fields(node):
            for child in value if isinstance(value, list) else [value]:
                if isinstance(child, ast.AST):
                    kind = _test_kind(node, field)
                    if kind == "if" and id(node) in self.elifs:
                        kind = "elif"
                    self.visit(child, self.site(kind, child) if kind else site, names)


def _scan_lights(root: Path) -> tuple[list[dict], list[dict]]:
    classes = light_classes(root)
    sites, replaces = [], []
    for rel, path in modules(root):
        if _excluded(rel):
            continue
        source, tree = parse(path)
        walker = _Sites(rel, source, classes)
        walker.visit(tree, None, frozenset(_bound_lights(tree, classes)))
        sites += [dict(s, test=_segment(source, s["test"]), reads=sorted(s["reads"]))
                  for s in walker.sites if s["reads"]]
        replaces += walker.replaces
    key = lambda s: (s["file"], s["line"], s.get("test", s.get("call")))  # noqa: E731
    return sorted(sites, key=key), sorted(replaces, key=key)


def light_branches(root: Path) -> list[dict]:
    """Every branch site on a light's kind outside the light packages (module docstring, 1)."""
    return _scan_lights(root)[0]


def light_replaces(root: Path) -> list[dict]:
    """Every ``replace`` of a light outside the light packages (module docstring, 1)."""
    return _scan_lights(root)[1]


def per_file(sites: list[dict]) -> dict[str, int]:
    """How many of ``sites`` each file holds, most first (then by name)."""
    counts = Counter(s["file"] for s in sites)
    return dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))


# ------------------------------------------------------------------------------ 2-4. modules, parameters

def loose_modules(root: Path) -> list[str]:
    """The ``.py`` files directly in ``mifaces/`` but ``__init__.py`` (root-relative, sorted)."""
    return sorted(f"{PACKAGE}/{p.name}" for p in (Path(root) / PACKAGE).glob("*.py") if p.name != "__init__.py")


def _public_module(rel: str) -> bool:
    parts = rel[:-len(".py")].split("/")
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return not any(p.startswith("_") for p in parts)


def parameter_counts(root: Path) -> list[dict]:
    """Every ``def`` in ``mifaces/`` with its number of parameters and whether it is public (module
    docstring, 3), sorted by file and line."""
    out = []

    def visit(node: ast.AST, rel: str, chain: tuple[tuple[str, str], ...]):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = child.args
                positional = [*a.posonlyargs, *a.args]
                if chain and chain[-1][0] == "class" and positional and positional[0].arg in ("self", "cls"):
                    positional = positional[1:]
                count = len(positional) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
                public = (_public_module(rel) and all(kind == "class" and not name.startswith("_")
                                                      for kind, name in chain) and not child.name.startswith("_"))
                out.append({"file": rel, "line": child.lineno,
                            "name": ".".join([*(name for _, name in chain), child.name]),
                            "parameters": count, "public": public})
                visit(child, rel, (*chain, ("function", child.name)))
            elif isinstance(child, ast.ClassDef):
                visit(child, rel, (*chain, ("class", child.name)))
            else:
                visit(child, rel, chain)

    for rel, path in modules(root):
        visit(parse(path)[1], rel, ())
    return sorted(out, key=lambda f: (f["file"], f["line"], f["name"]))


def long_modules(root: Path, limit: int = MAX_LINES) -> list[dict]:
    """The modules of ``mifaces/`` of more than ``limit`` lines, longest first."""
    out = [{"file": rel, "lines": len(parse(path)[0].splitlines())} for rel, path in modules(root)]
    return sorted((m for m in out if m["lines"] > limit), key=lambda m: (-m["lines"], m["file"]))


# ----------------------------------------------------------------------------------------- 5. fit_brdf

def fit_brdf_size(root: Path) -> list[dict]:
    """Each top-level ``def fit_brdf`` of ``mifaces/reflectance/``: where, its length in lines, and the lines
    where it calls ``fit_brdf`` by name."""
    out = []
    for rel, path in modules(root, f"{PACKAGE}/reflectance"):
        for node in parse(path)[1].body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == "fit_brdf":
                first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
                calls = sorted({c.lineno for c in ast.walk(node) if isinstance(c, ast.Call)
                                and isinstance(c.func, ast.Name) and c.func.id == "fit_brdf"})
                out.append({"file": rel, "line": node.lineno, "lines": node.end_lineno - first + 1,
                            "calls_itself": bool(calls), "self_calls": calls})
    return out


# ------------------------------------------------------------------------------------------ 6. CLI flags

def _click_option_names(tree: ast.Module) -> set[str]:
    """The names ``click.option`` goes by in a module: ``click.option`` (``import click [as c]``) and
    ``from click import option [as o]``."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {f"{a.asname or a.name}.option" for a in node.names if a.name == "click"}
        elif isinstance(node, ast.ImportFrom) and node.module == "click" and not node.level:
            names |= {a.asname or a.name for a in node.names if a.name == "option"}
    return names


def click_options(root: Path) -> list[dict]:
    """Every ``click.option(...)`` call of ``mifaces/``: its flag's long name (None: built at run time),
    declarations, ``type=`` and ``default=`` expressions."""
    out = []
    for rel, path in modules(root):
        source = path.read_text(encoding="utf-8")
        if "click" not in source:  # a quick skip; the syntax tree decides
            continue
        source, tree = parse(path)
        spellings = _click_option_names(tree)
        if not spellings:
            continue
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Call) and _dotted(node.func) in spellings):
                continue
            decls = []
            for arg in node.args:
                decls.append(arg.value if isinstance(arg, ast.Constant) and isinstance(arg.value, str) else None)
            longs = [part for d in decls if d for part in d.split("/") if part.startswith("--")]
            keywords = {k.arg: _text(k.value) for k in node.keywords if k.arg}
            default = next((k.value for k in node.keywords if k.arg == "default"), None)
            out.append({"file": rel, "line": node.lineno, "flag": longs[0] if longs and None not in decls[:1] else None,
                        "declaration": ", ".join(_segment(source, a) for a in node.args),
                        "type": keywords.get("type"), "default": keywords.get("default"),
                        "default_refers": default is not None and not isinstance(default, ast.Constant)})
    return sorted(out, key=lambda o: (o["file"], o["line"]))


def duplicate_flags(root: Path, options: list[dict] | None = None) -> dict[str, list[dict]]:
    """The flags declared in more than one place: long name -> its declarations (sorted); ``options``:
    ``click_options(root)`` where already made."""
    groups: dict[str, list[dict]] = {}
    for option in click_options(root) if options is None else options:
        if option["flag"] is not None:
            groups.setdefault(option["flag"], []).append(option)
    return {flag: found for flag, found in sorted(groups.items()) if len(found) > 1}


def copied_flags(duplicates: dict[str, list[dict]]) -> dict[str, list[dict]]:
    """Of ``duplicates``, the declarations that share a ``default=`` expression that is not a literal
    (``default(FitOptions, "resolution")``, not ``None``) with another of the same flag: one option of the
    API copied ("--flag [default]" -> declarations)."""
    out = {}
    for flag, found in duplicates.items():
        by_default: dict[str, list[dict]] = {}
        for option in found:
            if option["default_refers"]:
                by_default.setdefault(option["default"], []).append(option)
        for default, same in sorted(by_default.items()):
            if len(same) > 1:
                out[f"{flag} [{default}]"] = same
    return out


# ------------------------------------------------------------------------------------ 7. export's names

def brdf_model_names(root: Path) -> set[str]:
    """The ``name = "..."`` of every class in ``mifaces/brdf/``."""
    names = set()
    for _, path in modules(root, f"{PACKAGE}/brdf"):
        for cls in ast.walk(parse(path)[1]):
            if isinstance(cls, ast.ClassDef):
                for stmt in cls.body:
                    if isinstance(stmt, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "name"
                                                            for t in stmt.targets) \
                            and isinstance(stmt.value, ast.Constant) and isinstance(stmt.value.value, str):
                        names.add(stmt.value.value)
    return names


def _literals(node: ast.AST) -> list[str] | None:
    """The strings of a string literal or of a tuple, list or set of them (None: not such a literal)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)) and node.elts and all(
            isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.elts):
        return [e.value for e in node.elts]
    return None


def export_name_checks(root: Path) -> list[dict]:
    """Comparisons of a BRDF model's name with a string literal in ``mifaces/export/`` (module docstring, 7)."""
    models = brdf_model_names(root)
    out = []
    if not (Path(root) / PACKAGE / "export").is_dir():
        return out
    for rel, path in modules(root, f"{PACKAGE}/export"):
        source, tree = parse(path)
        for node in ast.walk(tree):
            if not isinstance(node, ast.Compare):
                continue
            operands = [node.left, *node.comparators]
            for op, left, right in zip(node.ops, operands, operands[1:]):
                if not isinstance(op, (ast.Eq, ast.NotEq, ast.In, ast.NotIn)):
                    continue
                for side, other in ((left, right), (right, left)):
                    strings = _literals(other)
                    if strings is None or _literals(side) is not None:
                        continue
                    if set(strings) & models or _last_name(side) in MODEL_NAMES:
                        out.append({"file": rel, "line": node.lineno, "comparison": _segment(source, node)})
                        break
                else:
                    continue
                break
    return sorted(out, key=lambda c: (c["file"], c["line"], c["comparison"]))


# ---------------------------------------------------------------------------- 8. sys.path in validation/

def sys_path_inserts(root: Path) -> list[dict]:
    """The scripts ``validation/*.py`` that call ``sys.path.insert``, with the lines."""
    out = []
    for path in sorted((Path(root) / "validation").glob("*.py")):
        if "sys.path" not in path.read_text(encoding="utf-8"):  # a quick skip; the syntax tree decides
            continue
        tree = parse(path)[1]
        lines = sorted({n.lineno for n in ast.walk(tree) if isinstance(n, ast.Call)
                        and _dotted(n.func) == "sys.path.insert"})
        if lines:
            out.append({"file": path.relative_to(root).as_posix(), "lines": lines})
    return out


# -------------------------------------------------------------------------------- 9. pipeline read-backs

def _absolute(rel: str, module: str | None, level: int) -> str:
    """The absolute module ``from {'.' * level}{module} import ...`` names in the file ``rel``."""
    if not level:
        return module or ""
    package = rel[:-len(".py")].split("/")[:-1]  # a module's package (an __init__'s too: its own folder)
    base = package[:len(package) - level + 1]
    return ".".join(base + ([module] if module else []))


def pipeline_reads(root: Path) -> list[dict]:
    """Calls of ``load_*``/``read_*`` functions of ``mifaces`` in the pipeline's modules (module docstring, 9)."""
    out = []
    for under in PIPELINE:
        if not (Path(root) / under).exists():
            continue
        for rel, path in modules(root, under):
            source, tree = parse(path)
            functions: dict[str, str] = {}   # local name -> "module.function"
            packages: dict[str, str] = {}    # local name of a mifaces module -> its name
            own = rel[:-len(".py")].replace("/", ".").removesuffix(".__init__")
            for node in tree.body:
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    functions[node.name] = f"{own}.{node.name}"
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom):
                    origin = _absolute(rel, node.module, node.level)
                    if origin.split(".")[0] == PACKAGE:
                        for a in node.names:
                            functions[a.asname or a.name] = f"{origin}.{a.name}"
                            packages[a.asname or a.name] = f"{origin}.{a.name}"
                elif isinstance(node, ast.Import):
                    for a in node.names:
                        if a.name.split(".")[0] == PACKAGE:
                            packages[a.asname or a.name.split(".")[0]] = a.asname and a.name or a.name.split(".")[0]
            for node in ast.walk(tree):
                if not isinstance(node, ast.Call):
                    continue
                func, origin = node.func, None
                if isinstance(func, ast.Name) and func.id in functions:
                    origin = functions[func.id]
                elif isinstance(func, ast.Attribute) and _dotted(func.value) in packages:
                    origin = f"{packages[_dotted(func.value)]}.{func.attr}"
                name = origin.rsplit(".", 1)[-1].lstrip("_") if origin else ""
                if name.startswith(("load_", "read_")) or name in FOLDER_READERS:
                    arguments = [*node.args, *(k.value for k in node.keywords)]
                    if name in FOLDER_READERS:
                        arguments = [*node.args[:1], *(k.value for k in node.keywords if k.arg == "result")]
                    out.append({"file": rel, "line": node.lineno, "function": origin,
                                "call": _segment(source, node)[:160],
                                "reads_its_output": any(isinstance(n, ast.Name) and n.id == "out"
                                                        for a in arguments for n in ast.walk(a))})
    return sorted(out, key=lambda c: (c["file"], c["line"], c["call"]))


# -------------------------------------------------------------------------------------------- together

#: The summary's rows: metric key -> what it counts.
LABELS = {
    "light_branches": "branch sites on a light's kind (outside mifaces/lights, light_estimation)",
    "light_replaces": "replace() of a light",
    "loose_modules": "loose modules in mifaces/",
    "functions_15_parameters": f"functions with >= {MAX_PARAMETERS} parameters",
    "public_over_10_parameters": f"public functions with > {MAX_PUBLIC_PARAMETERS} parameters",
    "long_modules": f"modules over {MAX_LINES} lines",
    "fit_brdf_lines": "fit_brdf's length (lines)",
    "fit_brdf_calls_itself": "fit_brdf calls itself",
    "duplicate_flags": "CLI flags declared more than once (by long name)",
    "copied_flags": "... of them one option copied (same default)",
    "export_name_checks": "BRDF name checks in export",
    "sys_path_inserts": "validation scripts with sys.path.insert",
    "pipeline_reads": "reads back of the pipeline's own output folder",
}


def _metric(key: str, count, sites, issue=None) -> dict:
    target, source = TARGETS.get(key, (None, None))
    met = None if target is None else (count == target if isinstance(target, bool) else count <= target)
    return {"count": count, "issue_count": issue, "target": target, "target_from": source, "met": met,
            "sites": sites}


def measure(root: Path = REPO) -> dict:
    """Every metric of the module docstring on the tree at ``root``."""
    root = Path(root)
    branches, replaces = _scan_lights(root)
    functions = parameter_counts(root)
    many = [f for f in functions if f["parameters"] >= MAX_PARAMETERS]
    public = [f for f in functions if f["public"] and f["parameters"] > MAX_PUBLIC_PARAMETERS]
    by_count = Counter(f["parameters"] for f in functions)
    fits = fit_brdf_size(root)
    options = click_options(root)
    duplicates = duplicate_flags(root, options)
    copies = copied_flags(duplicates)
    dynamic = [o for o in options if o["flag"] is None]
    loose, lengths, names, inserts, reads = (loose_modules(root), long_modules(root), export_name_checks(root),
                                            sys_path_inserts(root), pipeline_reads(root))
    metrics = {
        "light_branches": dict(_metric("light_branches", len(branches), branches, ISSUE["light_branches"]),
                               files=len(per_file(branches)), issue_files=ISSUE["light_branch_files"],
                               per_file=per_file(branches)),
        "light_replaces": _metric("light_replaces", len(replaces), replaces, ISSUE["light_replaces"]),
        "loose_modules": _metric("loose_modules", len(loose), loose, ISSUE["loose_modules"]),
        "functions_15_parameters": _metric("functions_15_parameters", len(many), many,
                                           ISSUE["functions_15_parameters"]),
        "public_over_10_parameters": _metric("public_over_10_parameters", len(public), public,
                                             ISSUE["public_over_10_parameters"]),
        "long_modules": _metric("long_modules", len(lengths), lengths),
        "fit_brdf_lines": _metric("fit_brdf_lines", fits[0]["lines"] if len(fits) == 1 else None, fits),
        "fit_brdf_calls_itself": _metric("fit_brdf_calls_itself", any(f["calls_itself"] for f in fits), fits),
        "duplicate_flags": _metric("duplicate_flags", len(duplicates), duplicates),
        "copied_flags": _metric("copied_flags", len(copies), copies),
        "export_name_checks": _metric("export_name_checks", len(names), names),
        "sys_path_inserts": _metric("sys_path_inserts", len(inserts), inserts),
        "pipeline_reads": dict(_metric("pipeline_reads", sum(r["reads_its_output"] for r in reads),
                                       [r for r in reads if r["reads_its_output"]]),
                               pipeline_calls=reads),
    }
    for key, metric in metrics.items():
        metric["label"] = LABELS[key]
    return {
        "issue": '49 ("One owner per stage")',
        "note": "Counted with Python's ast by validation/design_metrics.py; its docstring states each rule. "
                "issue_count: the issue's figure when it was written; target_from: where the target comes from.",
        "parameter_rule": "positional-only, positional, keyword-only, *args and **kwargs count one each; a "
                          "method's self/cls is left out",
        "parameter_distribution": [{"parameters": n, "functions": by_count[n]} for n in sorted(by_count)],
        "functions": len(functions),
        "modules": len(modules(root)),
        "dynamic_flags": dynamic,
        "metrics": metrics,
    }


def summary_rows(data: dict) -> list[list[str]]:
    """metric / issue / now / target / met, one row per metric."""
    def show(x):
        return "-" if x is None else ("yes" if x is True else "no" if x is False else str(x))
    return [[m.get("label", key), show(m.get("issue_count")), show(m.get("count")), show(m.get("target")),
             show(m.get("met"))] for key, m in data["metrics"].items()]


def print_summary(data: dict) -> None:
    rows = [["metric", "issue", "now", "target", "met"], *summary_rows(data)]
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    for row in rows:
        print("  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip())
    print("\nbranch sites on a light's kind, per file:")
    for name, n in data["metrics"]["light_branches"]["per_file"].items():
        print(f"  {n:3d}  {name}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=REPO, help="the repository's root (default: this one)")
    parser.add_argument("--out", type=Path, default=REPO / "validation" / "results" / "design_metrics.json")
    args = parser.parse_args(argv)
    data = measure(args.root)
    print_summary(data)
    write_result(args.out, data, script=__file__, argv=argv and [sys.argv[0], *argv])
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
