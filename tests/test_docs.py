"""The Python examples of the README and docs/ run as written, and do what their text says;
every relative link of the README and docs/ resolves."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
_BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def python_blocks(doc: str) -> list[str]:
    """The ```python blocks of ``doc`` (a path relative to the repository root), in order."""
    blocks = _BLOCK.findall((ROOT / doc).read_text())
    assert blocks, f"{doc} has no python example"
    return blocks


def run_blocks(doc: str) -> dict:
    """Execute every python block of ``doc`` in order, in one namespace (later blocks use what
    earlier ones made, as a reader would); returns the namespace."""
    namespace: dict = {"__name__": "__doc_example__"}
    for i, block in enumerate(python_blocks(doc)):
        exec(compile(block, f"{doc} python block {i + 1}", "exec"), namespace)
    return namespace


def test_readme_python_api_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    torch.set_num_threads(1)
    ns = run_blocks("README.md")
    seq, demos = ns["seq"], ns["demos"]  # seq: the model loaded back from model.pt
    assert (tmp_path / "model.pt").is_file()
    # the loaded model is the fitted one: the same seed fits it again bit for bit
    x = demos[1].features[::10]
    again = ns["ConcurrentSequencer"].fit(demos, seed=0)
    np.testing.assert_array_equal(seq.progress(x), again.progress(x))
    assert seq.events == []  # a loaded model starts with no episode
    # the replay stepped every variable: one active MP per graph, each a node of its graph
    active = ns["active"]
    assert set(active) == set(seq.graphs)
    assert all(mp in seq.graphs[v].nodes for v, mp in active.items())


def test_guide_python_api_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    torch.set_num_threads(1)
    ns = run_blocks("docs/guide.md")
    seq, demos = ns["seq"], ns["demos"]  # seq: the model loaded back from model.pt
    assert (tmp_path / "model.pt").is_file()
    # the block replayed a demonstration through `seq.events[-1]` (an empty list would have
    # raised); the loaded model is the fitted one: the same seed fits it again bit for bit
    x = demos[1].features[::10]
    again = ns["ConcurrentSequencer"].fit(demos, seed=0)
    np.testing.assert_array_equal(seq.progress(x), again.progress(x))
    assert seq.events == []  # a loaded model starts with no episode
    # the batch: one {variable: MP} per episode, an initial node of each graph (one 10 ms
    # tick after the start is too early for any switch)
    assert len(ns["actives"]) == 4
    for active in ns["actives"]:
        assert set(active) == set(seq.graphs)
        assert all(mp in seq.graphs[v].initial_nodes for v, mp in active.items())
    # PAPER_OPTIONS is the paper's method: no coupling, no recovery, independent starts
    paper = ns["paper"]
    assert (paper.config.coupling, paper.config.recovery) == ("none", False)
    assert paper.config.start_rule == "independent"
    assert (paper.config.switch_rule, seq.config.switch_rule) == ("paper", "peak")
    # the worlds block: a fitted sequencer and the world's scripted policy on held-out contexts
    learned, fair = ns["learned"], ns["fair"]
    assert fair.counts == {"complete": 10, "wrong_start": 0, "incomplete": 0}
    assert sum(learned.counts.values()) == 10 and learned.world == "relay"
    assert set(ns["world_names"]()) >= {"relay", "peg", "slip", "procedural"}


def test_data_format_examples_run_and_load(tmp_path, monkeypatch):
    from cpmp.data.datafile import load_demonstrations

    monkeypatch.chdir(tmp_path)
    ns = run_blocks("docs/data_format.md")
    # the file written by hand with h5py is a valid demonstration file
    (by_hand,) = load_demonstrations(tmp_path / "my_robot.hdf5", split="train")
    assert [a.mp for a in by_hand.segments("right_hand")] == ["reach", "grasp"]
    assert [a.mp for a in by_hand.segments("left_hand")] == ["hold"]
    np.testing.assert_array_equal(by_hand.features, ns["features"])
    # the API example's claims, as its comments state them
    demo = ns["demo"]
    assert [(a.mp, a.start, a.stop) for a in demo.segments("right_hand")] == [
        ("reach", 0, 100),
        ("grasp", 100, 201),
    ]
    np.testing.assert_array_equal(demo.switch_indices("right_hand"), [100])
    assert ns["list_splits"]("demos.hdf5") == {"train": ["demo_0"]}
    (loaded,) = ns["train"]
    np.testing.assert_array_equal(loaded.features, demo.features)
    assert loaded.metadata == demo.metadata


_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
_FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces -> '-'."""
    text = heading.lstrip("#").strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = _FENCE.sub("", path.read_text(encoding="utf-8"))
    return {slug(line) for line in text.splitlines() if re.match(r"^#{1,6} ", line)}


def broken_links(docs: list[Path]) -> list[str]:
    """Every relative link of ``docs`` whose file, or heading in it, does not exist."""
    broken = []
    for doc in docs:
        text = _FENCE.sub("", doc.read_text(encoding="utf-8"))
        for target in _LINK.findall(text):
            if re.match(r"^[a-z]+:", target):  # http(s):, mailto: ...
                continue
            file, _, anchor = target.partition("#")
            path = (doc.parent / file).resolve() if file else doc
            if not path.exists():
                broken.append(f"{doc.name}: {target} (no such file)")
            elif anchor and path.suffix == ".md" and anchor not in anchors(path):
                broken.append(f"{doc.name}: {target} (no such heading)")
    return broken


def test_every_relative_link_resolves():
    docs = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    broken = broken_links(docs)
    assert not broken, "\n".join(broken)


def test_the_link_check_sees_a_broken_link(tmp_path):
    assert slug("## The main job: `scripts/experiment.py`") == "the-main-job-scriptsexperimentpy"
    assert slug("### Bring your own robot's recordings") == "bring-your-own-robots-recordings"
    (tmp_path / "a.md").write_text("# Top\n\n```\n# not a heading\n```\n")
    assert anchors(tmp_path / "a.md") == {"top"}
    links = "[a](a.md) [b](a.md#top) [c](https://x.org/y) [d](gone.md) [e](a.md#not-a-heading)"
    (tmp_path / "b.md").write_text(links + "\n")
    assert broken_links([tmp_path / "b.md"]) == [
        "b.md: gone.md (no such file)",
        "b.md: a.md#not-a-heading (no such heading)",
    ]
