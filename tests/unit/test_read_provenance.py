"""`read_provenance` of a CSV whose sidecar, or a netCDF file whose attribute, is valid JSON but
no record: a ValueError naming the file (a list came back as the provenance, and each reader's
`.get` failed on it)."""

import json
import re

import pytest

from taichi_star.output import read_provenance
from taichi_star.provenance import table_stamp


@pytest.mark.parametrize("text", ["[1]", "42", '"model"', "null", "true"])
def test_a_sidecar_that_is_no_json_object_holds_no_provenance(tmp_path, text):
    table = tmp_path / "t.csv"
    table.write_text("a\n1\n")
    sidecar = tmp_path / "t.csv.json"
    sidecar.write_text(text)
    with pytest.raises(ValueError, match=rf"^{re.escape(str(sidecar))}: no taichi_star "
                                         rf"provenance in it \(not a JSON object\)$"):
        read_provenance(table)


def test_a_sidecar_object_is_the_provenance(tmp_path):
    table = tmp_path / "t.csv"
    table.write_text("a\n1\n")
    facts = {"model": {"preset": "paper"}, **table_stamp(1, table.read_bytes())}
    (tmp_path / "t.csv.json").write_text(json.dumps(facts))
    assert read_provenance(table) == facts


def test_a_netcdf_attribute_that_is_no_json_object_holds_no_provenance(tmp_path):
    """The netCDF branch returned its attribute unchecked (the CSV's check came after it)."""
    xr = pytest.importorskip("xarray")
    path = tmp_path / "t.nc"
    xr.Dataset({"a": ("x", [1.0])}, attrs={"provenance": "[1]"}).to_netcdf(path)
    with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: no taichi_star "
                                         rf"provenance in it \(not a JSON object\)$"):
        read_provenance(path)
    xr.Dataset({"a": ("x", [1.0])}, attrs={"provenance": '{"model": null}'}).to_netcdf(path)
    assert read_provenance(path) == {"model": None}
