"""Report figures: formats and resolution, legends that explain the marks, log axis and zoom, chosen trial."""

from PIL import Image
from typer.testing import CliRunner

from preland_app.campaign.report import summarize
from preland_app.campaign.store import ResultsStore
from preland_app.cli import app

from .test_field_records import seeded_store
from .test_store_reading import add_events_and_path


def report(db, out, *args):
    return CliRunner().invoke(app, ["campaign", "report", str(db), "--out", str(out), *map(str, args)])


def test_png_at_300_dpi_by_default_and_vector_formats(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    add_events_and_path(db)
    result = report(db, tmp_path / "png")
    assert result.exit_code == 0, result.output
    pngs = sorted((tmp_path / "png").glob("*.png"))
    assert [p.name for p in pngs] == ["thesis_table3_ecdf.png", "thesis_table3_errors.png",
                                      "thesis_table3_positions.png", "thesis_table3_trajectory.png"]
    for path in pngs:
        with Image.open(path) as image:
            assert round(image.info["dpi"][0]) == 300 and image.width >= 7 * 300
    assert report(db, tmp_path / "low", "--dpi", "120").exit_code == 0
    with Image.open(tmp_path / "low" / "thesis_table3_errors.png") as image:
        assert round(image.info["dpi"][0]) == 120
    assert report(db, tmp_path / "pdf", "--format", "pdf").exit_code == 0
    pdfs = sorted((tmp_path / "pdf").glob("*.pdf"))
    assert len(pdfs) == 4 and all(p.read_bytes()[:5] == b"%PDF-" for p in pdfs)
    assert "thesis_table3_errors.pdf" in (tmp_path / "pdf" / "thesis_table3.md").read_text()
    result = report(db, tmp_path / "x", "--format", "gif")
    assert result.exit_code == 2 and "--format" in result.stderr
    assert report(db, tmp_path / "x", "--dpi", "5").exit_code == 2


def test_legends_say_what_every_mark_means_and_errors_over_two_orders_get_a_log_axis(tmp_path):
    db = seeded_store(tmp_path / "r.db")  # errors 3 and 4 cm
    assert CliRunner().invoke(app, ["trial", "record", str(db), "thesis_table3", "None / none",
                                    "--error-cm", "400", "--x-cm", "0", "--y-cm",
                                    "400"]).exit_code == 0
    assert report(db, tmp_path / "svg", "--format", "svg").exit_code == 0
    errors = (tmp_path / "svg" / "thesis_table3_errors.svg").read_text()
    for text in ("box: middle 50 % of simulated trials", "box: middle 50 % of field trials", "line in box: median",
                 "whiskers: minimum to maximum", "diamond: mean", "dot: one published trial", "bar: published mean",
                 "landing error (cm, log scale)"):
        assert text in errors, text
    positions = (tmp_path / "svg" / "thesis_table3_positions.svg").read_text()
    assert "filled circle: simulated" in positions and "hollow diamond: published" in positions
    assert "within" in positions  # the zoomed panel beside the full one
    from preland_app.campaign.figures import _zoom_radius_cm, spans_two_orders  # matplotlib: not at collection

    assert spans_two_orders([1.0, 100.0]) and not spans_two_orders([1.0, 99.0]) and not spans_two_orders([0.0, 5])
    assert _zoom_radius_cm([1.0, 2.0, 3.0, 4.0, 150.0]) == 5 and _zoom_radius_cm([20.0, 40.0]) is None


def test_a_linear_axis_when_errors_stay_within_two_orders(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    assert report(db, tmp_path / "svg", "--format", "svg").exit_code == 0
    errors = (tmp_path / "svg" / "thesis_table3_errors.svg").read_text()
    assert "landing error (cm)" in errors and "log scale" not in errors
    assert "box: middle 50 % of field trials" not in errors  # no field rows: no legend entry for them


def test_field_rows_keep_their_scenarios_colour_and_scenarios_stay_distinct(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    runner = CliRunner()
    for label in ("None / none", "IRLock / none"):
        assert runner.invoke(app, ["trial", "record", str(db), "thesis_table3", label,
                                   "--error-cm", "5"]).exit_code == 0
    with ResultsStore(db) as store:
        summaries = summarize(store, "thesis_table3")
    from preland_app.campaign.figures import scenario_colors  # matplotlib: not at collection

    colors = scenario_colors(summaries)
    assert len(summaries) == 4 and len(colors) == 2 and len(set(colors.values())) == 2
    many = [type("S", (), {"scenario": f"s{i}", "label": f"s{i}"})() for i in range(15)]
    assert len(set(scenario_colors(many).values())) == 15


def test_the_trajectory_figure_shows_the_chosen_trial(tmp_path):
    db = seeded_store(tmp_path / "r.db")
    add_events_and_path(db)
    result = report(db, tmp_path / "svg", "--format", "svg", "--campaign", "thesis_table3", "--trial",
                    "IRLock / none:2")
    assert result.exit_code == 0, result.output
    path = (tmp_path / "svg" / "thesis_table3_trajectory.svg").read_text()
    assert "IRLock / none, sim trial 2" in path and "landing error 5.0 cm" in path
    assert "last 2 m of the descent" in path  # the path (about 2.4 m) is long beside a 5 cm error
    result = report(db, tmp_path / "svg", "--campaign", "thesis_table3", "--trial", "IRLock / none")
    assert result.exit_code == 2 and "SCENARIO:INDEX" in result.stderr
    result = report(db, tmp_path / "none", "--campaign", "thesis_table3", "--trial", "IRLock / none:7")
    assert result.exit_code == 2 and "no trial 7" in result.stderr
    assert not list((tmp_path / "none").glob("*.png"))  # a trial that is not there is found before any drawing
