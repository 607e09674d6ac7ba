"""``pendulab docs``: where the built documentation site is (issue 23). The site's own build runs in CI
(.ci/run: sphinx-build -W); these tests cover the command's answers."""

from __future__ import annotations

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
