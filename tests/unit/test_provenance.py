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
    assert s["commit"] is None and s["dirty"] is None and "dirty_paths" not in s
    # the machine a number needs: CPU, cores, the thread settings (XLA_FLAGS moves ZeroEGGS' parameters)
    assert s["cpu"] == provenance.cpu_model() and s["cores"] >= 1 and isinstance(s["threads"], dict)


def test_stamp_records_the_thread_settings(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert provenance.stamp({})["threads"].get("XLA_FLAGS") == "--xla_cpu_multi_thread_eigen=false"
    monkeypatch.delenv("XLA_FLAGS")
    assert "XLA_FLAGS" not in provenance.stamp({})["threads"]


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
    assert provenance.dirty_paths(tmp_path / "pkg") == []
    (tmp_path / "README.md").write_text("edited\n")  # any other tracked file counts
    assert provenance.commit_of(tmp_path / "pkg")[1] is True
    assert provenance.dirty_paths(tmp_path / "pkg") == ["README.md"]  # a dirty stamp names its dirty paths
    assert provenance.stamp({}, repo=tmp_path)["dirty_paths"] == ["README.md"]
    assert provenance.dirty_paths(tmp_path / "pkg", limit=0) == ["... and 1 more"]
    h1 = provenance.stamp({}, repo=tmp_path)["diff_sha256"]
    (tmp_path / "README.md").write_text("edited again\n")
    assert provenance.code_stamp(repo=tmp_path)["diff_sha256"] != h1  # another diff, another hash
    (tmp_path / "experiments/e/results/r.json").write_text("[1]\n")  # results: not in the hash
    assert provenance.diff_sha256(tmp_path) == provenance.code_stamp(repo=tmp_path)["diff_sha256"]
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


def test_evaluation_stamp_carries_the_training_code(tmp_path):
    """A training writes its code stamp into config.json; a result evaluated from that workdir carries it."""
    wd = tmp_path / "wd"
    wd.mkdir()
    code = provenance.code_stamp(command=["jaxgest", "zeggs", "train"])
    (wd / "config.json").write_text(json.dumps({"model": "zeggs", "code": code}))
    s = provenance.read_results(provenance.write_results(tmp_path / "r.json", {}, {"x": 1}, workdir=wd))["stamp"]
    assert s["training"] == code and s["training"]["command"] == "jaxgest zeggs train"
    (wd / "config.json").write_text(json.dumps({"model": "zeggs"}))  # a workdir from before the code stamp
    assert provenance.stamp({}, workdir=wd)["training"] is None
    assert "training" not in provenance.stamp({})
