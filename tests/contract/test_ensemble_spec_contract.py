"""Ensemble sampling specs: each --sample distribution's parameters are finite numbers meeting the
distribution's rule, and each --samples CSV cell of a numeric parameter is a finite number, checked where the spec is
read (linknet_core/ensemble/command.py) with an error naming the parameter (or the file, line and column), the
distribution and the rule; the CLI says it in one line, never numpy's traceback."""
import subprocess
import sys

import pytest

from contract_support import MODELS, ROOT
import linknet_core as ln
from linknet_core.ensemble.command import parse_sample, read_samples_csv

CHAIN = MODELS / "chain_10.json"


@pytest.mark.parametrize("text,words", [
    ("U0[11,1]=normal:0:-1", "SD = -1 is negative; the normal distribution (normal:MEAN:SD) needs SD >= 0"),
    ("M[3]=uniform:2:1", "LOW = 2 is above HIGH = 1; the uniform distribution (uniform:LOW:HIGH) needs LOW <= HIGH"),
    ("M[3]=uniform:-1e308:1e308", "HIGH - LOW = inf overflows; the uniform distribution"),
    ("M[3]=normal:1e400:1", "MEAN = '1e400' of the normal distribution (normal:MEAN:SD) must be a finite number"),
    ("M[3]=uniform:0:1e999", "HIGH = '1e999' of the uniform distribution"),
])
def test_a_distribution_whose_parameters_break_its_rule_is_refused_naming_them(text, words):
    with pytest.raises(ln.LinknetError) as err:
        parse_sample(text)
    assert f"--sample {text!r}: " in str(err.value) and words in str(err.value), str(err.value)


@pytest.mark.parametrize("text", ["M[3]=uniform:1:1", "M[3]=normal:1:0", "M[3]=uniform:0.5:2", "U0[11,1]=normal:0:1"])
def test_a_distribution_within_its_rule_is_read(text):
    name, distribution, a, b = parse_sample(text)
    assert name == text.partition("=")[0] and distribution.problem(a, b) is None


@pytest.mark.parametrize("content,words", [
    ("M[3],M[4]\n1,2\nabc,3\n", "line 3, column 1 (M[3]): 'abc' is not a finite number"),
    ("M[3],M[4]\n1,nan\n", "line 2, column 2 (M[4]): 'nan' is not a finite number"),
    ("M[3],M[4]\n1,\n", "line 2, column 2 (M[4]): '' is not a finite number"),
    ("M[3],M[4]\n1,2\n3\n", "line 3 has 1 value(s), the header names 2 (M[3], M[4])"),
    ("M[3],M[4]\n1,2,3\n", "line 2 has 3 value(s), the header names 2"),
    ("M[3]\n", "no parameter sets below the header"),
])
def test_a_samples_csv_cell_that_is_not_a_number_is_refused_naming_file_line_and_column(content, words, tmp_path):
    path = tmp_path / "samples.csv"
    path.write_text(content)
    with pytest.raises(ln.LinknetError) as err:
        read_samples_csv(str(path), ln.load_scene(CHAIN))
    assert str(err.value).startswith(f"--samples {path}: ") and words in str(err.value), str(err.value)


def test_a_good_samples_csv_is_read_column_by_column(tmp_path):
    path = tmp_path / "samples.csv"
    path.write_text("M[3], integrator\n1.5,rattle\n2,dop853\n")
    columns = read_samples_csv(str(path), ln.load_scene(CHAIN))
    assert list(columns["M[3]"]) == [1.5, 2.0] and list(columns["integrator"]) == ["rattle", "dop853"]


@pytest.mark.parametrize("args,words", [
    (["--sample", "U0[11,1]=normal:0:-1"], "SD = -1 is negative"),
    (["--sample", "M[3]=uniform:2:1"], "LOW = 2 is above HIGH = 1"),
    (["--samples", "CSV"], "line 3, column 1 (M[3]): 'abc' is not a finite number"),
])
def test_cli_answers_a_bad_sampling_spec_in_one_line(args, words, tmp_path):
    csv = tmp_path / "samples.csv"
    csv.write_text("M[3]\n1\nabc\n")
    args = [str(csv) if a == "CSV" else a for a in args]
    proc = subprocess.run([sys.executable, "-m", "linknet_core.cli", "ensemble", str(CHAIN), *args, "--t-end", "0.1",
                           "--n-samples", "2", "--no-progress"], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.startswith("linknet ensemble: error: ") and proc.stderr.count("\n") == 1, proc.stderr
    assert words in proc.stderr
