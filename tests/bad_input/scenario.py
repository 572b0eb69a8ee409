"""Scenario TOML: every key's wrong type, range and spelling, and files that are not TOML at all."""

from __future__ import annotations

from pathlib import Path

import momentid as mi

from ._core import Case, Group, Outcome

#: A two-storey scenario small enough to simulate in milliseconds (0.5 s at 200 Hz).
BASE = """\
[scenario]
name = "tiny"
duration = 0.5
sample_rate = 200.0

[structure]
masses = [10.0, 12.0]
storey_stiffness = [2000.0, 1500.0]

[structure.damping]
rayleigh_mu = 0.05
rayleigh_kappa = 0.001

[excitation]
type = "harmonic"
amplitude = 0.002
angular_frequency = 6.2832

[[runs]]
name = "ref"
added_mass = [0.0, 0.0]

[[runs]]
name = "m1"
added_mass = [0.5, 0.5]
"""


def write(folder: Path, old: str = "", new: str = "", text: str | None = None) -> Path:
    """``BASE`` with ``old`` replaced by ``new`` (``old`` must occur), or ``text``, as ``s.toml``."""
    if text is None:
        assert old in BASE, old
        text = BASE.replace(old, new, 1)
    path = folder / "s.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _load(old="", new="", text=None):
    return lambda folder: mi.load_scenario(write(folder, old, new, text))


def _simulate(old="", new=""):
    return lambda folder: mi.simulate(mi.load_scenario(write(folder, old, new)))


def _error(id_, old, new, *names, xfail=None):
    return Case(Group.SCENARIO, id_, Outcome.ERROR, _load(old, new), ("s.toml", *names), xfail)


#: (id, replaced text, replacement, what the message must name).
_BAD_KEYS = [
    ("duration-negative", "duration = 0.5", "duration = -1.0", "duration", "-1.0"),
    ("duration-zero", "duration = 0.5", "duration = 0.0", "duration"),
    ("duration-string", "duration = 0.5", 'duration = "long"', "duration", "long"),
    ("duration-nan", "duration = 0.5", "duration = nan", "duration", "nan"),
    ("duration-inf", "duration = 0.5", "duration = inf", "duration", "inf"),
    ("sample-rate-negative", "sample_rate = 200.0", "sample_rate = -200.0", "sample_rate", "-200"),
    ("sample-rate-bool", "sample_rate = 200.0", "sample_rate = true", "sample_rate", "True"),
    ("sample-rate-array", "sample_rate = 200.0", "sample_rate = [200.0]", "sample_rate"),
    ("unknown-key", "sample_rate = 200.0", "sample_rate = 200.0\nsampel_rate = 3", "sampel_rate"),
    ("unknown-table", "[excitation]", "[excitaton]\ntype = \"harmonic\"\n[excitation]", "excitaton"),
    ("name-with-slash", 'name = "tiny"', 'name = "../../etc/evil"', "name", "../../etc/evil"),
    ("masses-negative", "masses = [10.0, 12.0]", "masses = [10.0, -12.0]", "masses", "-12"),
    ("masses-empty", "masses = [10.0, 12.0]", "masses = []", "masses"),
    ("masses-strings", "masses = [10.0, 12.0]", 'masses = ["10", "12"]', "masses"),
    ("stiffness-length", "storey_stiffness = [2000.0, 1500.0]", "storey_stiffness = [2000.0, 1500.0, 1.0]",
     "storey_stiffness"),
    ("stiffness-zero", "storey_stiffness = [2000.0, 1500.0]", "storey_stiffness = [2000.0, 0.0]",
     "storey_stiffness"),
    ("stiffness-missing", "storey_stiffness = [2000.0, 1500.0]\n", "", "storey_stiffness"),
    ("masses-missing", "masses = [10.0, 12.0]\n", "", "masses"),
    ("mu-negative", "rayleigh_mu = 0.05", "rayleigh_mu = -0.05", "rayleigh_mu", "-0.05"),
    ("kappa-string", "rayleigh_kappa = 0.001", 'rayleigh_kappa = "small"', "rayleigh_kappa", "small"),
    ("damping-both-forms", "rayleigh_kappa = 0.001", "rayleigh_kappa = 0.001\ndamping_ratios = [0.02, 0.03]",
     "damping_ratios"),
    ("excitation-type-unknown", 'type = "harmonic"', 'type = "earthquake"', "type", "earthquake"),
    ("amplitude-negative", "amplitude = 0.002", "amplitude = -0.002", "amplitude", "-0.002"),
    ("frequency-both", "angular_frequency = 6.2832", "angular_frequency = 6.2832\nfrequency = 1.0", "frequency"),
    ("frequency-missing", "angular_frequency = 6.2832\n", "", "frequency"),
    ("record-file-missing", 'type = "harmonic"\namplitude = 0.002\nangular_frequency = 6.2832',
     'type = "record"\nfile = "nowhere.at2"', "nowhere.at2"),
    ("added-mass-length", "added_mass = [0.5, 0.5]", "added_mass = [0.5, 0.5, 0.5]", "added_mass"),
    ("added-mass-negative", "added_mass = [0.5, 0.5]", "added_mass = [0.5, -0.5]", "added_mass", "-0.5"),
    ("run-name-duplicate", 'name = "m1"', 'name = "ref"', "ref"),
    ("run-name-path", 'name = "m1"', 'name = "../m1"', "name", "../m1"),
    ("runs-not-array", "[[runs]]\nname = \"ref\"\nadded_mass = [0.0, 0.0]\n\n[[runs]]\nname = \"m1\"\n"
     "added_mass = [0.5, 0.5]\n", "[runs]\nname = \"ref\"\n", "runs"),
    ("sensors-set-unknown", "[[runs]]\nname = \"ref\"", "[sensors]\nset = \"gyro\"\n\n[[runs]]\nname = \"ref\"",
     "set", "gyro"),
    ("sensors-rate-not-divisor", "[[runs]]\nname = \"ref\"",
     "[sensors]\nsample_rate = 70.0\n\n[[runs]]\nname = \"ref\"", "sample_rate", "70"),
    ("sensor-noise-negative", "[[runs]]\nname = \"ref\"",
     "[sensors.accelerometer]\nnoise = -1.0\n\n[[runs]]\nname = \"ref\"", "noise", "-1"),
    ("substeps-zero", "[[runs]]\nname = \"ref\"", "[simulation]\nsubsteps = 0\n\n[[runs]]\nname = \"ref\"",
     "substeps", "0"),
    ("truth-mechanism-unknown", "[[runs]]\nname = \"ref\"",
     "[[truth.mechanisms]]\ntype = \"magic\"\n\n[[runs]]\nname = \"ref\"", "type", "magic"),
    ("truth-storey-out-of-range", "[[runs]]\nname = \"ref\"",
     "[[truth.mechanisms]]\ntype = \"coulomb_friction\"\nstorey = 7\nforce = 0.3\n\n[[runs]]\nname = \"ref\"",
     "storey", "7"),
    # issue 22: finite but absurd values overflowed inside the simulation (a traceback from an eigen-solver)
    ("masses-1e308", "masses = [10.0, 12.0]", "masses = [1e308, 12.0]", "structure.masses[0]", "1e+308", "kg"),
    ("masses-1e-308", "masses = [10.0, 12.0]", "masses = [10.0, 1e-308]", "structure.masses[1]", "1e-308"),
    ("stiffness-1e308", "storey_stiffness = [2000.0, 1500.0]", "storey_stiffness = 1e308",
     "storey_stiffness", "1e+308", "N/m"),
    ("mu-1e308", "rayleigh_mu = 0.05", "rayleigh_mu = 1e308", "rayleigh_mu", "1e+308"),
    ("kappa-1e308", "rayleigh_kappa = 0.001", "rayleigh_kappa = 1e308", "rayleigh_kappa", "1e+308"),
    ("base-mass-1e-20", "storey_stiffness = [2000.0, 1500.0]",
     "storey_stiffness = [2000.0, 1500.0]\nbase_mass = 1e-20", "base_mass", "1e-20"),
    ("storey-height-1e308", "storey_stiffness = [2000.0, 1500.0]",
     "storey_stiffness = [2000.0, 1500.0]\nstorey_height = 1e308", "storey_height", "1e+308"),
    ("added-mass-1e308", "added_mass = [0.5, 0.5]", "added_mass = [1e308, 0.5]", "added_mass[0]", "1e+308"),
    ("amplitude-1e308", "amplitude = 0.002", "amplitude = 1e308", "excitation.amplitude", "1e+308", "m"),
    ("angular-frequency-1e308", "angular_frequency = 6.2832", "angular_frequency = 1e308",
     "angular_frequency", "1e+308"),
    ("frequency-1e308", "angular_frequency = 6.2832", "frequency = 1e308", "excitation.frequency", "1e+308", "Hz"),
    ("tracking-error-1e308", 'type = "harmonic"', 'type = "harmonic"\ntracking_error = 1e308',
     "tracking_error", "1e+308"),
]

def _not_utf8(folder: Path):
    path = folder / "s.toml"
    path.write_bytes(b"[scenario]\nname = \"\xff\xfe\"\n")
    return mi.load_scenario(path)


def _garbage(folder: Path):
    path = folder / "s.toml"
    path.write_bytes(bytes(range(256)))
    return mi.load_scenario(path)


CASES = [_error(id_, old, new, *names) for id_, old, new, *names in _BAD_KEYS] + [
    Case(Group.SCENARIO, "toml-syntax", Outcome.ERROR, _load(text="[scenario\nname = 1\n"), ("s.toml", "line")),
    Case(Group.SCENARIO, "empty-file", Outcome.ERROR, _load(text=""), ("s.toml",)),
    Case(Group.SCENARIO, "not-utf8", Outcome.ERROR, _not_utf8, ("s.toml",)),
    Case(Group.SCENARIO, "binary-garbage", Outcome.ERROR, _garbage, ("s.toml",)),
    Case(Group.SCENARIO, "missing-file", Outcome.ERROR, lambda f: mi.load_scenario(f / "nothing.toml"),
         ("nothing.toml",)),
    Case(Group.SCENARIO, "a-folder", Outcome.ERROR, lambda f: mi.load_scenario(f), (),),
    Case(Group.SCENARIO, "sample-rate-1e12", Outcome.REFUSAL,
         _simulate("sample_rate = 200.0", "sample_rate = 1e12"), ("samples", "refused")),
    Case(Group.SCENARIO, "duration-9e305", Outcome.ERROR, _load("duration = 0.5", "duration = 8.98846567431158e+305"),
         ("s.toml", "duration")),
    Case(Group.SCENARIO, "duration-1e9", Outcome.REFUSAL,
         _simulate("duration = 0.5", "duration = 1e9"), ("refused",)),
]
