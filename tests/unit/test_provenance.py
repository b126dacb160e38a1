import json

import pytest

from jaxgest.runtime import provenance
from jaxgest.runtime.errors import DataError


def test_stamp_names_commit_version_config_command(tmp_path):
    cfg = {"preset": "tiny", "seed": 3, "nested": {"lr": 1e-3}}
    p = provenance.write_results(tmp_path / "r.json", {"score": 0.5}, cfg, command=["jaxgest", "x", "--y", "a b"])
    obj = provenance.read_results(p)
    s = obj["stamp"]
    assert s["config"] == cfg
    assert s["command"] == "jaxgest x --y 'a b'"
    assert s["version"] == __import__("jaxgest").__version__
    assert obj["results"] == {"score": 0.5}
    # tmp_path is outside any checkout: the stamp says so rather than guessing
    assert s["commit"] is None and s["dirty"] is None


def test_commit_inside_this_checkout():
    commit, dirty = provenance.commit_of()
    if commit is None:
        pytest.skip("package not inside a git checkout")
    assert len(commit) == 40 and isinstance(dirty, bool)


def test_dirty_means_code_not_results(tmp_path):
    import shutil
    import subprocess

    if shutil.which("git") is None:
        pytest.skip("no git")

    def git(*args):
        subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=tmp_path, check=True,
                       capture_output=True)

    files = {"pkg/code.py": "x = 1\n", "experiments/e/out/claims_a.md": "a\n", "experiments/e/results/r.json": "{}\n",
             "experiments/e/README.md": "table\n", "README.md": "root\n"}
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    git("init", "-q")
    git("add", "-A")
    git("commit", "-q", "-m", "init")
    assert provenance.commit_of(tmp_path / "pkg")[1] is False
    (tmp_path / "experiments/e/out/claims_a.md").write_text("rewritten by an evaluation\n")
    (tmp_path / "experiments/e/results/r.json").write_text("[]\n")
    (tmp_path / "experiments/e/out/new.json").write_text("{}\n")  # untracked: never counted
    (tmp_path / "experiments/e/README.md").write_text("table rewritten by a run beside this one\n")
    assert provenance.commit_of(tmp_path / "pkg")[1] is False
    (tmp_path / "README.md").write_text("edited\n")  # any other tracked file counts
    assert provenance.commit_of(tmp_path / "pkg")[1] is True
    (tmp_path / "README.md").write_text("root\n")
    (tmp_path / "pkg/code.py").write_text("x = 2\n")
    assert provenance.commit_of(tmp_path / "experiments/e")[1] is True


@pytest.mark.parametrize("content", ["{", json.dumps({"results": {}}), json.dumps({"stamp": {"commit": "x"}, "results": {}})])
def test_unstamped_file_refused(tmp_path, content):
    p = tmp_path / "bad.json"
    p.write_text(content)
    with pytest.raises(DataError, match="bad.json"):
        provenance.read_results(p)


def test_process_command_can_be_typed_again(tmp_path):
    root = tmp_path
    (root / "experiments" / "x").mkdir(parents=True)
    script = root / "experiments" / "x" / "evaluate.py"
    cfg = root / "experiments" / "x" / "configs" / "a.toml"
    assert provenance.process_command([str(script), str(cfg), "--seed", "1"], root) == [
        "python", "experiments/x/evaluate.py", "experiments/x/configs/a.toml", "--seed", "1"]
    main = root / "experiments" / "__main__.py"
    assert provenance.process_command([str(main), "run", "/elsewhere/c.toml"], root) == [
        "python", "-m", "experiments", "run", "/elsewhere/c.toml"]  # outside root: kept as given
    assert provenance.process_command(["/usr/bin/jaxgest", "bench"], root) == ["jaxgest", "bench"]
