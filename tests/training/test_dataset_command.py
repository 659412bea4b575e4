"""The dataset command's user errors are one line and exit status 2: a Ray address where no cluster answers
(it hung past 580 s), a manifest.json that is a list, bad JSON, a directory or of the wrong shape, and an
--out that cannot be a folder. None of these starts Ray."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from viewer.scene import SceneError
from viewer.training import dataset_cli, generate

ROOT = Path(__file__).resolve().parents[2]
SMALL = ["--train", "1", "--val", "0", "--splits", "train", "--probes", "4", "--voxels", "8", "--directions", "16"]


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:"), err
    return err[0]


@pytest.mark.parametrize("content, says", [
    ("[1, 2]", "a manifest is a JSON object, this is a list"),
    ("{", "not a readable manifest"),
    ("\xff\xfe", "not a readable manifest"),
    ("[" * 100000, "not a readable manifest"),
    ('{"splits": []}', "its 'splits' is a list"),
    ('{"splits": {"train": 3}}', "'splits' are not objects of shards"),
    ('{"timing": {"rooms_made": "many"}}', "'timing' holds something other than numbers"),
])
def test_a_tampered_manifest_is_one_line_and_exit_2(tmp_path, capsys, content, says):
    (tmp_path / "manifest.json").write_bytes(content.encode("latin-1"))
    assert dataset_cli.main(["--out", str(tmp_path), *SMALL]) == 2
    assert says in one_error_line(capsys)


def test_a_manifest_that_is_a_directory_or_a_pipe_is_one_line_and_exit_2(tmp_path, capsys):
    (tmp_path / "a" / "manifest.json").mkdir(parents=True)
    assert dataset_cli.main(["--out", str(tmp_path / "a"), *SMALL]) == 2
    assert "a directory" in one_error_line(capsys)
    (tmp_path / "b").mkdir()
    os.mkfifo(tmp_path / "b" / "manifest.json")
    assert dataset_cli.main(["--out", str(tmp_path / "b"), *SMALL]) == 2
    assert "not a regular file" in one_error_line(capsys)


def test_an_out_that_is_a_file_is_one_line_and_exit_2(tmp_path, capsys):
    (tmp_path / "file").write_text("")
    assert dataset_cli.main(["--out", str(tmp_path / "file"), *SMALL]) == 2
    assert "file" in one_error_line(capsys)


def test_an_address_where_nothing_listens_is_refused_without_waiting_on_ray():
    with pytest.raises(SceneError, match="no Ray cluster answers there"):
        generate.check_address("127.0.0.1:1")
    with pytest.raises(SceneError, match="no Ray cluster answers there"):
        generate.check_address("ray://no-such-host.invalid:10001")
    with pytest.raises(SceneError, match="expected host:port"):
        generate.check_address("127.0.0.1:http")
    generate.check_address("auto")   # left to Ray


def test_the_command_with_a_dead_address_exits_2_in_one_line(tmp_path):
    # the timeout guards against the hang this is about; the assertion is the exit status and the line
    result = subprocess.run([sys.executable, "-m", "viewer.training.dataset", "--out", str(tmp_path / "data"),
                             "--address", "127.0.0.1:1", *SMALL], capture_output=True, text=True, timeout=300,
                            cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --address 127.0.0.1:1"), result.stderr
    manifest = tmp_path / "data" / "manifest.json"
    assert not manifest.exists() or isinstance(json.loads(manifest.read_text()), dict)


def test_an_address_that_answers_but_is_not_ray_is_one_line_after_a_few_tries(monkeypatch):
    """Something listens (here a bare socket) but no Ray GCS answers: Ray is asked to try a few times, not
    its default 20 of about 40 s each, and its ConnectionError becomes one line. ray.init is replaced here:
    the real one measured 128 s for 3 tries."""
    import socket

    import ray

    tried = {}

    def init(**kwargs):
        tried["tries"] = os.environ.get("RAY_gcs_server_port_wait_time_s")
        raise ConnectionError(f"Failed to connect to Ray cluster at {kwargs['address']}")

    monkeypatch.delenv("RAY_gcs_server_port_wait_time_s", raising=False)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", init)
    with socket.socket() as listening:
        listening.bind(("127.0.0.1", 0))
        listening.listen(1)
        address = f"127.0.0.1:{listening.getsockname()[1]}"
        with pytest.raises(SceneError, match=f"--address {address}: cannot join that Ray cluster") as refused:
            generate.start_ray(None, address)
    assert tried["tries"] == str(generate.JOIN_TRIES) and "\n" not in str(refused.value)
