"""The accuracy/speed harness (bench/accuracy.py) runs end to end and writes what the manual quotes.

A small run (one scene, low sample counts) proves the command produces the JSON, the markdown
tables and the plot, with every method placed on Cycles' error/time curve for lighting and AO.
The figures of a real run are in bench/results and docs/benchmarks.md; here only their shape and sense count.
"""
import json

import pytest

from scenes import script


def test_equal_error_time_interpolates_and_extrapolates_on_the_log_log_curve():
    accuracy = script("bench/accuracy.py")
    errors, seconds = [0.4, 0.2, 0.1], [1.0, 4.0, 16.0]  # error ∝ t^-1/2
    t, extrapolated = accuracy.equal_error_seconds(errors, seconds, 0.2 / 2 ** 0.5)
    assert t == pytest.approx(8.0) and not extrapolated
    t, extrapolated = accuracy.equal_error_seconds(errors, seconds, 0.05)
    assert t == pytest.approx(64.0) and extrapolated
    t, extrapolated = accuracy.equal_error_seconds([0.2], [2.0], 0.05)  # one point: Monte Carlo's rate
    assert t == pytest.approx(32.0) and extrapolated


@pytest.mark.slow
def test_accuracy_bench_writes_tables_and_plot_for_lighting_and_ao(tmp_path):
    accuracy = script("bench/accuracy.py")
    assert accuracy.main(["--scenes", "lamp_scene", "--methods", "direct", "bunnell",
                          "--samples", "4", "16", "--reference-samples", "64", "--device", "cpu",
                          "--output", str(tmp_path)]) == 0
    (json_path,) = tmp_path.glob("accuracy-*.json")
    results = json.loads(json_path.read_text())
    scene = results["scenes"]["lamp_scene"]
    lighting, ao = scene["lighting"], scene["ao"]
    assert [c["samples"] for c in lighting["cycles"]] == [4, 16]
    # Cycles converges: 16 samples are closer to the truth than 4
    assert lighting["cycles"][1]["relative_rmse"] < lighting["cycles"][0]["relative_rmse"]
    assert ao["cycles"][1]["mean_abs_error"] < ao["cycles"][0]["mean_abs_error"]
    by_method = {o["method"]: o for o in lighting["ours"]}
    # direct light alone misses the indirect part, Bunnell's bounce brings some of it back
    assert by_method["direct"]["mean_bias"] < by_method["bunnell"]["mean_bias"] < 0.1
    assert by_method["bunnell"]["relative_rmse"] < by_method["direct"]["relative_rmse"]
    (ours_ao,) = ao["ours"]
    assert ours_ao["mean_abs_error"] < 0.1
    for row in lighting["ours"] + ao["ours"]:
        assert row["seconds"] > 0 and row["speedup_at_equal_error"] > 0
    table = json_path.with_suffix(".md").read_text()
    assert "| lamp_scene | **bunnell** (cpu) |" in table and "| lamp_scene | **ao** (cpu) |" in table
    assert json_path.with_suffix(".png").stat().st_size > 10_000


@pytest.mark.slow
def test_accuracy_bench_lightmap_mode_places_our_page_on_cycles_curves(tmp_path):
    """Small pages: a truth at one size, Cycles' noise from pairs of bakes at a larger one, and an
    extrapolated one; each with our error, Cycles' curve and the equal-error speedups."""
    accuracy = script("bench/accuracy.py")
    assert accuracy.main(["--lightmap", "--truth-size", "48", "--samples", "4", "16", "--reference-samples",
                          "128", "--pair-sizes", "64", "--pair-samples", "4", "256", "--extrapolated-sizes",
                          "96", "--output", str(tmp_path)]) == 0
    (json_path,) = tmp_path.glob("accuracy-lightmap-*.json")
    sizes = json.loads(json_path.read_text())["lightmap"]["sizes"]
    assert list(sizes) == ["48", "64", "96"] and sizes["96"]["extrapolated"]
    # The pairs' top count resolves our error: ours² = |ours − pair mean|² − σ²/2, and at 16 spp
    # σ²/2 (relative 0.29² / 2) dwarfs ours² (0.05²), so the estimate was noise around it.
    for size, row in sizes.items():
        assert [c["samples"] for c in row["cycles"]] == ([4, 16] if size == "48" else [4, 256])
        assert row["cycles"][1]["relative_rmse"] < row["cycles"][0]["relative_rmse"]
        assert 0 < row["ours_relative_rmse"] < row["cycles"][0]["relative_rmse"]
        assert row["speedup_vs_cycles"] > 0 and row["ours_seconds"] > 0
        if accuracy._oidn() is not None:
            assert row["speedup_vs_cycles_oidn"] > 0 and "denoised_relative_rmse" in row["cycles"][0]
    assert "**ours**" in json_path.with_suffix(".md").read_text()
    assert json_path.with_suffix(".png").stat().st_size > 10_000


def test_accuracy_bench_cost_mode_times_our_page_per_texel_at_each_size(tmp_path):
    """--lightmap-cost: our Cornell page at two sizes, no Cycles; a larger page covers more texels
    and each row's µs per texel is its seconds over its texels; a page too large is refused."""
    accuracy = script("bench/accuracy.py")
    assert accuracy.main(["--lightmap-cost", "32", "64", "16384", "--output", str(tmp_path)]) == 0
    (json_path,) = tmp_path.glob("accuracy-lightmap-cost-cornell_box-*.json")
    rows = json.loads(json_path.read_text())["cost"]["sizes"]
    # a page over the memory a bake may use is refused, said, and the other sizes kept
    assert [r["max_size"] for r in rows] == [32, 64, 16384] and "memory" in rows.pop()["refused"]
    assert 0 < rows[0]["texels"] < rows[1]["texels"] and max(rows[1]["size"]) <= 64
    for r in rows:
        assert r["microseconds_per_texel"] == pytest.approx(1e6 * r["seconds"] / r["texels"], rel=0.01, abs=0.01)
        assert r["stages"] and max(r["stages"].values()) <= 1.05 * r["seconds"]  # no stage outlasts the bake
    assert "µs per texel" in json_path.with_suffix(".md").read_text()
    assert json_path.with_suffix(".png").stat().st_size > 10_000


@pytest.mark.slow
def test_accuracy_bench_direct_mode_places_each_light_sample_count_on_cycles_direct_curve(tmp_path):
    """--passes direct: Cycles' Direct pass as the truth, our direct light at each sample count and
    emitter selection, no AO; the file says which passes it compared."""
    accuracy = script("bench/accuracy.py")
    assert accuracy.main(["--scenes", "lamp_scene", "--passes", "direct", "--light-samples", "4", "32",
                          "--light-selections", "exact", "--samples", "4", "16", "--reference-samples", "64",
                          "--device", "cpu", "--output", str(tmp_path)]) == 0
    (json_path,) = tmp_path.glob("accuracy-direct-*.json")
    scene = json.loads(json_path.read_text())["scenes"]["lamp_scene"]
    assert scene["passes"] == "direct" and "ao" not in scene
    ours = {o["method"]: o for o in scene["lighting"]["ours"]}
    assert set(ours) == {"direct exact 4", "direct exact 32"}
    # direct light alone against a direct-only truth: no missing indirect part, more samples closer
    assert abs(ours["direct exact 32"]["mean_bias"]) < 0.05
    assert ours["direct exact 32"]["relative_rmse"] < ours["direct exact 4"]["relative_rmse"]
