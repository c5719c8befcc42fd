"""The ``abu`` program's matplotlib start-up (:mod:`abu.cli.figure_startup`): matplotlib's
generated ``set()`` docstrings are skipped, and nothing a user sees changes -- the same figure
bytes as a process that builds them, ``set()`` still works, the module's source is still found.
The speed it buys is measured by ``benchmarks/bench_measure.py``, not here."""
from __future__ import annotations

import json
import subprocess
import sys
import types
from pathlib import Path

import pytest

import abu.cli.figure_startup as fs

ROOT = Path(__file__).resolve().parents[1]

# run in a fresh process: `abu measure --tracks` through the CLI's main(), with or without the
# start-up the program installs, then what a user could observe of matplotlib
_MEASURE = r'''
import inspect, json, sys
if sys.argv[1] == "install":
    from abu.cli.figure_startup import install
    assert install()
from abu.cli.main import main
status = main(["measure", sys.argv[2], "--tracks", "--out", sys.argv[3]])
import matplotlib.lines as lines
import matplotlib.artist as artist
line = lines.Line2D([0, 1], [0, 1])
line.set(color="red", linewidth=2.5)           # set() itself, with a property and an alias
line.set(lw=1.5)
class Sub(lines.Line2D):                       # a user's subclass still gets its own set()
    pass
print(json.dumps({"status": status, "doc": len(lines.Line2D.set.__doc__ or ""),
                  "color": line.get_color(), "lw": line.get_linewidth(),
                  "sub_own_set": Sub.set is not lines.Line2D.set,
                  "source": len(inspect.getsource(artist.Artist.set))}))
'''


@pytest.fixture(scope="module")
def tracks_csv(tmp_path_factory) -> Path:
    from synthetic_tracks import measured_pixels, simulate, write_tracks_csv

    record = simulate(0.02, "steps", n=1500)
    x, y = measured_pixels(record, sigma_px=0.02, harmonic_px=0.4, seed=5)
    return write_tracks_csv(tmp_path_factory.mktemp("tracks") / "tracks.csv", record, x, y)


def _measure(mode: str, tracks: Path, out: Path) -> dict:
    done = subprocess.run([sys.executable, "-c", _MEASURE, mode, str(tracks), str(out)],
                          capture_output=True, text=True, cwd=ROOT, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_the_same_figures_and_set_without_the_generated_docstrings(tmp_path, tracks_csv):
    plain = _measure("plain", tracks_csv, tmp_path / "plain")
    quick = _measure("install", tracks_csv, tmp_path / "quick")
    assert plain["status"] == quick["status"] == 0
    # the start-up took effect (no generated docstring) where it was installed, only there
    assert plain["doc"] > 1000 and quick["doc"] == 0
    for key in ("color", "lw", "sub_own_set"):
        assert quick[key] == plain[key], key
    assert quick["sub_own_set"] and quick["lw"] == 1.5 and quick["source"] > 0
    for name in ("beta.png", "kinematics.png", "summary.json"):
        assert (tmp_path / "quick" / name).read_bytes() == \
            (tmp_path / "plain" / name).read_bytes(), name


def test_the_program_installs_it_and_the_api_does_not(monkeypatch):
    import abu.cli.main as cli_main
    import abu.cli.process_exit as process_exit

    calls = []
    monkeypatch.setattr(fs, "install", lambda: calls.append("install") or True)
    monkeypatch.setattr(cli_main, "main", lambda: 0)

    def fake_exit(status):
        raise SystemExit(status)

    monkeypatch.setattr(process_exit, "exit_process", fake_exit)
    with pytest.raises(SystemExit):
        cli_main.console_main()
    assert calls == ["install"]
    done = subprocess.run(
        [sys.executable, "-c", "import sys, abu.api\n"
         "print(any(type(f).__name__ == '_ArtistFinder' for f in sys.meta_path))"],
        capture_output=True, text=True, cwd=ROOT, check=True)
    assert done.stdout.strip() == "False"


def test_nothing_is_patched_where_matplotlib_has_no_such_step():
    assert not fs.patch_artist(types.ModuleType("no_artist"))

    class Artist:      # a matplotlib that builds its docstrings another way
        pass

    module = types.ModuleType("matplotlib.artist")
    module.Artist = Artist
    assert not fs.patch_artist(module)
    assert not hasattr(Artist, "_update_set_signature_and_docstring")


def test_install_is_a_no_op_once_matplotlib_artist_is_loaded(monkeypatch):
    monkeypatch.setitem(sys.modules, fs.ARTIST_MODULE, types.ModuleType(fs.ARTIST_MODULE))
    before = list(sys.meta_path)
    assert not fs.install()
    assert sys.meta_path == before
