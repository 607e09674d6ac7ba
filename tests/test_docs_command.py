"""``pendulab docs``: where the built documentation site is (issue 23). The site's own build runs in CI
(.ci/run: sphinx-build -W); these tests cover the command's answers."""

from __future__ import annotations

from pathlib import Path

from pendulab.cli import docs
from pendulab.cli.main import main


def test_prints_the_built_site(monkeypatch, tmp_path, capsys):
    index = tmp_path / "docs" / "_build" / "html" / "index.html"
    index.parent.mkdir(parents=True)
    index.write_text("<html></html>")
    monkeypatch.setattr(docs, "site_paths", lambda: (tmp_path / "docs", index))
    assert main(["docs"]) == 0
    assert capsys.readouterr().out.strip() == str(index)


def test_says_how_to_build_it(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(docs, "site_paths", lambda: (tmp_path / "docs", tmp_path / "docs" / "_build" / "html" / "index.html"))
    assert main(["docs"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not built yet: 'pendulab docs --build' writes" in err


def test_an_installed_package_points_to_a_checkout(monkeypatch, capsys):
    monkeypatch.setattr(docs, "site_paths", lambda: (None, None))
    assert main(["docs"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install -e .[docs]" in err


def test_the_checkout_has_a_sphinx_site():
    source, index = docs.site_paths()
    assert (source / "conf.py").is_file() and index.name == "index.html"
    for page in ("index.md", "install.md", "student.md", "ta.md", "fmi.md", "api.rst", "protocol.md", "firmware.md"):
        assert (source / page).is_file(), page


def test_api_docstrings_have_no_bare_substitution_bars():
    """CI builds the site with -W; the usual break is ``|x|`` written bare in a docstring, which reStructuredText
    reads as an undefined substitution. Checked here, cheaply, for every module the API reference lists."""
    import re

    source, _ = docs.site_paths()
    modules = re.findall(r"^   (pendulab[\w.]*)$", (source / "api.rst").read_text(), re.M)
    assert len(modules) > 30
    bare = re.compile(r"(?<![\w|`])\|[A-Za-z_][\w.]*\|(?![\w|`])")
    found = []
    for module in modules:
        path = source.parent / "src" / Path(*module.split("."))
        path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
        for number, line in enumerate(path.read_text().splitlines(), 1):
            text = re.sub(r"``.*?``", "", re.sub(r"(^|\s)#(?!:).*$", "", line))  # plain comments are not documentation
            if bare.search(text):
                found.append(f"{path.relative_to(source.parent)}:{number}: {line.strip()}")
    assert not found, "write ``|x|`` instead (the docs build reads |x| as a substitution):\n" + "\n".join(found)
