"""The bad-input corpus: every command, configuration file, trajectory and sound-speed file and study file
given something wrong, run as a user runs it: each command in a process of its own (forked from one that imported
the CLI once, :func:`_command`).

Each case must end with exit status 2, no traceback, one line ``sblsim: error: ...`` naming the field (or
argparse's one line for a malformed option), and the working folder unchanged byte for byte: the output of
an earlier run kept, nothing new written, no temporary folder left. The cases run two at a time; each has
a folder of its own holding the files it needs and an earlier result that must survive.
"""

from __future__ import annotations

import hashlib
import multiprocessing
import multiprocessing.connection
import os
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from sblsim.orchestrator.io.manifest import write_manifest

BIG = "1" + "0" * 400
LOG_HEADER = "time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n"
#: Parquet logs (name -> schema metadata: the configuration an exported log carries).
PARQUET = {"model_log.parquet": '[simulation]\nreceiver = "model:exits.py"\n',
           "deep_log.parquet": "[platform]\nbaseline = " + "[" * 30000 + "]" * 30000 + "\n"}
#: Named pipes: a reader that opened one would wait for a writer (the case's timeout).
FIFOS = ("fifo_log.csv", "fifo.toml")

#: Files a case may refer to (written into its folder before it runs).
FILES = {
    "bad.toml": "[platform\nbaseline = 3\n",
    "typed.toml": '[platform]\nbaseline = "three"\n',
    "section.toml": "[sonar]\ngain = 1\n",
    "receiver.toml": '[simulation]\nreceiver = "ekf"\n[receiver]\nalpha = 0.5\n',
    "nan_row.csv": "time,north,east,down\n0,0,0,5\nnan,1,1,5\n10,5,5,5\n",
    "typo_row.csv": "0,1x,0,5\n1,1,1,5\n10,5,5,5\n",
    "back_in_time.csv": "0,0,0,5\n5,1,1,5\n4,2,2,5\n",
    "names.csv": "a,b,c,d\n0,0,0,5\n10,5,5,5\n",
    "three.csv": "time,north,east,down\n0,0,0\n10,5,5\n",
    "above_surface.csv": "0,0,0,-5\n10,5,5,5\n",
    "one_row.csv": "0,0,0,5\n",
    "ssp_text.csv": "depth,sound_speed\n0,1500\n10,abc\n",
    "ssp_slow.csv": "depth,sound_speed\n0,1.5\n10,1500\n",
    "ssp_negative.csv": "depth,sound_speed\n-5,1500\n10,1500\n",
    "ssp_noheader.csv": "0,1500\n10,1490\n",
    "ssp_nan.csv": "depth,sound_speed\n0,1500\n10,nan\n",
    "nomodel.py": "x = 1\n",
    "broken.py": "import no_such_module\n",
    "notzip.ssp": "this is not a zip file",
    "study_bad.toml": "[study\n",
    "study_key.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\ncolour = "red"\n'
                      '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "study_level.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\n'
                        '[[factors]]\nname = "loss"\nkey = "acoustics.loss_pct"\nlow = 0\nhigh = 150\n',
    "study_ok.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\n'
                     '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "study_same.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\n'
                       '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 1\n',
    "study_swapped.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\n'
                          '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 3\nhigh = 1\n',
    "study_unknown_key.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\n'
                              '[[factors]]\nname = "b"\nkey = "platform.arm"\nlow = 1\nhigh = 3\n',
    "study_replicates.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 0\n'
                             '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "study_noscenario.toml": '[study]\nreplicates = 2\n'
                             '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "study_seed.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\nseed = -4\n'
                       '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "study_design.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\ndesign = "weird"\n'
                         '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "study_resolution.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\ndesign = "fractional"\n'
                             'resolution = 9\n[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\n'
                             'high = 3\n[[factors]]\nname = "g"\nkey = "platform.gps_sigma"\nlow = 0.1\nhigh = 1\n',
    "study_generators.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\ndesign = "fractional"\n'
                             'generators = "a b c"\n[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\n'
                             'high = 3\n',
    "study_scenario.toml": '[study]\nscenarios = ["atlantis"]\nreplicates = 2\n'
                           '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "study_set.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\n'
                      'set = ["acoustics.sound_speed_profile=ssp_slow.csv"]\n'
                      '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "study_alpha.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\n'
                        '[[factors]]\nname = "a"\nkey = "receiver.alpha"\nlow = 0.5\nhigh = 1\n',
    "study_reserved.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\n'
                           '[[factors]]\nname = "cell"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "study_receiver.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 2\n'
                           '[[factors]]\nname = "rx"\nkey = "simulation.receiver"\nlow = "ekf"\nhigh = "kalman"\n',
    "study_memory.toml": '[study]\nscenarios = ["semicircle"]\nreplicates = 100000\n'
                         'set = ["simulation.duration=100", "simulation.sampling_time=0.001"]\n'
                         '[[factors]]\nname = "b"\nkey = "platform.baseline"\nlow = 1\nhigh = 3\n',
    "exits.py": "import sys\nsys.exit(0)\n",
    "deep.toml": "[platform]\nbaseline = " + "[" * 30000 + "]" * 30000 + "\n",
    "deep_log.csv": "# sblsim log, format 1\n#% [platform]\n#% baseline = " + "[" * 30000 + "]" * 30000 + "\n"
                    + LOG_HEADER + "0.1,1,6,1,0,1,2\n",
    "model_log.csv": '#% [simulation]\n#% receiver = "model:exits.py"\n' + LOG_HEADER + "0.1,1,6,1,0,1,2\n",
    "fmu_log.csv": '#% [simulation]\n#% receiver = "fmu:emptyfmus/sblsim_platform.fmu.bak"\n' + LOG_HEADER
                   + "0.1,1,6,1,0,1,2\n",
    "underscore_log.csv": LOG_HEADER + "0.1,1,6,1,0,1,2\n0.2,2,1_0.0,0,1,1,2\n",
    "arabic_log.csv": LOG_HEADER + "0.1,1,6,1,0,1,2\n0.2,2,\u0666,0,1,1,2\n",
    "traj.csv": "0,0,0,5\n10,5,5,5\n",
    "good_log.csv": "time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n0.1,1,6,1,0,1,2\n"
                    "0.2,,,,,,2\n0.3,3,6,-1,0,1,2\n",
    "jump_log.csv": "time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n5,1,6,1,0,1,2\n"
                    "1,2,6,0,1,1,2\n",
    "typo_log.csv": "time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n0.1,1,6,1,0,1,2\n"
                    "0.2,2,6,0,1x,1,2\n",
    "truth_back.csv": "time_s,n_m,e_m,d_m\n0,0,0,2\n1,0,0,2\n0.5,0,0,2\n",
    "exported.csv": "an earlier export",
    "long_pass.csv": "0,0,0,5\n1e7,10,10,5\n",
    # 513 good rows, then a line that would be an error if it were read: reading stops at row 513
    "many_rows.csv": "".join(f"{k},0,0,5\n" for k in range(513)) + "x,y\n",
    "campaign/runs.parquet": "PAR1 not a parquet file",
    "campaign/study.toml": "[study\n",
    "nonempty/notes.txt": "mine",
    "earlier_run/summary.json": "{}",
    "earlier_map/map.csv": "east,north\n",
    "earlier_budget/budget.csv": "source,contribution\n",
    "earlier_design/design.json": "{}\n",
    "earlier.ssp": "an earlier package",
    "afile": "not a directory",
    "emptyfmus/.keep": "",
    "adir/.keep": "",
    # design problems
    "d_bad.toml": "[work_area\nradius_m = 3\n",
    "d_section.toml": '[design]\nscenario = "lbl-field"\n[sonar]\ngain = 1\n',
    "d_key.toml": '[design]\nscenario = "lbl-field"\n[work_area]\ncolour = "red"\n',
    "d_range.toml": '[design]\nscenario = "lbl-field"\n[prescription]\ndrms_m = -0.1\n',
    "d_nan.toml": '[design]\nscenario = "lbl-field"\n[prescription]\ndrms_m = nan\n',
    "d_type.toml": '[design]\nscenario = "lbl-field"\n[prescription]\ncoverage_pct = "most"\n',
    "d_length.toml": '[design]\nscenario = "lbl-field"\n[candidates]\ntransponders = [3]\n',
    "d_swapped.toml": '[design]\nscenario = "lbl-field"\n[candidates]\ntransponders = [8, 3]\n',
    "d_grade.toml": '[design]\nscenario = "lbl-field"\n[candidates]\ngps = ["best"]\n',
    "d_costs.toml": '[design]\nscenario = "lbl-field"\n[candidates]\ngps = ["dgps", "rtk"]\ngps_cost = [1]\n',
    "d_polygon.toml": '[design]\nscenario = "lbl-field"\n[seafloor]\navoid = ["0 0; 1 1; 2 2"]\n',
    "d_path.toml": '[design]\nscenario = "/etc/passwd"\n',
    "d_toml_path.toml": '[design]\nscenario = "earlier.toml"\n',
    "earlier.toml": '[simulation]\nreceiver = "model:exits.py"\n',
    "d_set_file.toml": '[design]\nscenario = "lbl-field"\nset = ["target.trajectory_file=/etc/passwd"]\n',
    "d_set_model.toml": '[design]\nscenario = "lbl-field"\nset = ["simulation.receiver=model:exits.py"]\n',
    "d_set_bad.toml": '[design]\nscenario = "lbl-field"\nset = ["platform.baseline=-3"]\n',
    "d_name.toml": '[design]\nname = "../escape"\nscenario = "lbl-field"\n',
    "d_floor.toml": '[design]\nscenario = "lbl-field"\n[seafloor]\ndepth_m = 100\n',
    "d_deep.toml": "[design]\nset = " + "[" * 40 + "]" * 40 + "\n",
    "d_big.toml": "# " + "x" * (1 << 20) + "\n",
}

T = ["--set", "target.trajectory=file", "--set"]
S = ["--set"]
#: id -> (arguments, text the one line must hold)
CASES = {
    # run: values
    "run zero baseline": (["run", "semicircle", "--set", "platform.baseline=0"], "platform.baseline"),
    "run text baseline": (["run", "semicircle", "--set", "platform.baseline=abc"], "platform.baseline"),
    "run infinite baseline": (["run", "semicircle", "--set", "platform.baseline=1e400"], "platform.baseline"),
    "run 400-digit integer": (["run", "semicircle", "--set", f"platform.beaufort={BIG}"], "platform.beaufort"),
    "run 400-digit seed": (["run", "semicircle", "--seed", BIG], "--seed"),
    "run negative seed": (["run", "semicircle", "--seed", "-1"], "--seed"),
    "run unknown section": (["run", "semicircle", "--set", "sonar.gain=1"], "sonar"),
    "run unknown key": (["run", "semicircle", "--set", "platform.arm=1"], "platform.arm"),
    "run no equals": (["run", "semicircle", "--set", "platform.baseline"], "platform.baseline"),
    "run loss above 100": (["run", "semicircle", "--set", "acoustics.loss_pct=101"], "acoustics.loss_pct"),
    "run negative sigma": (["run", "semicircle", "--set", "acoustics.sigma_range=-1"], "acoustics.sigma_range"),
    "run beaufort 9": (["run", "semicircle", "--set", "platform.beaufort=9"], "platform.beaufort"),
    # the inverted LBL: a receiver without the emission epoch, toa for another system, a jitter that would make
    # an interval negative, more hydrophones than a ping's arrivals in flight
    "run ilbl with the paper's ekf": (["run", "semicircle", "--set", "platform.system=ilbl"], "simulation.receiver"),
    "run toa on sbl": (["run", "semicircle", "--set", "acoustics.ranging=toa"], "acoustics.ranging"),
    "run ilbl jitter too large": (["run", "semicircle", "--set", "platform.system=ilbl", "--set", "receiver=ukf",
                                   "--set", "acoustics.ping_jitter=0.5"], "acoustics.ping_jitter"),
    # the pinger's types: rbi without its bounds, a key of another type, pbi without its table
    "run ilbl rbi without bounds": (["run", "semicircle", "--set", "platform.system=ilbl", "--set", "receiver=ukf",
                                     "--set", "acoustics.ping_type=rbi"], "acoustics.burst_interval_min"),
    "run ilbl sbi with rbi's key": (["run", "semicircle", "--set", "platform.system=ilbl", "--set", "receiver=ukf",
                                     "--set", "acoustics.burst_interval_max=2"], "acoustics.burst_interval_max"),
    "run ilbl pbi without table": (["run", "semicircle", "--set", "platform.system=ilbl", "--set", "receiver=ukf",
                                    "--set", "acoustics.ping_type=pbi"], "acoustics.burst_sequence"),
    "run ilbl 9 hydrophones": (["run", "semicircle", "--set", "platform.system=ilbl", "--set", "receiver=ukf",
                                "--set", "platform.layout=circle", "--set", "platform.beacons=9"],
                               "platform.beacons"),
    "run beaufort 2.5": (["run", "semicircle", "--set", "platform.beaufort=2.5"], "platform.beaufort"),
    "run sampling time 0": (["run", "semicircle", "--set", "simulation.sampling_time=0"],
                            "simulation.sampling_time"),
    "run duration below T": (["run", "semicircle", "--set", "simulation.duration=0.01"], "simulation.duration"),
    "run duration not a multiple of T": (["run", "semicircle", "--set", "simulation.duration=5",
                                          "--set", "simulation.sampling_time=0.3"],
                                         "simulation.duration: 5 s is not a whole number"),
    "run duration beyond memory": (["run", "semicircle", "--set", "simulation.duration=1e6",
                                    "--set", "simulation.sampling_time=0.001"],
                                   "simulation.duration: 1000000 s at T = 0.001 s is 1000000000 steps"),
    "run vanishing baseline": (["run", "semicircle", "--set", "platform.baseline=1e-300"], "platform.baseline"),
    "run beacons at one point": (["run", "semicircle", "--set", "platform.layout=custom",
                                  "--set", "platform.beacon_offsets=1 1 1; 1 1 1; 1 1 1; 1 1 1"],
                                 "platform.beacon_offsets"),
    "run ratio 0": (["run", "semicircle", "--set", "simulation.ekf_rate_ratio=0"], "simulation.ekf_rate_ratio"),
    "run master newton": (["run", "semicircle", "--set", "simulation.master=newton"], "simulation.master"),
    "run master event on the local engine": (["run", "semicircle", "--master", "event"], "simulation.master"),
    "run fmi version 5": (["run", "semicircle", "--set", "simulation.fmi_version=5"], "simulation.fmi_version"),
    "run trajectory choice": (["run", "semicircle", "--set", "target.trajectory=zigzag"], "target.trajectory"),
    "run tiny sigma_range": (["run", "semicircle", "--set", "receiver.sigma_range=1e-9"], "receiver.sigma_range"),
    "run layout offsets": (["run", "semicircle", "--set", "platform.layout=custom",
                            "--set", "platform.beacon_offsets=1 2; 3"], "platform.beacon_offsets"),
    # run: scenarios and configuration files
    "run unknown scenario": (["run", "atlantis"], "scenario"),
    "run missing config": (["run", "missing.toml"], "config"),
    "run directory config": (["run", "adir"], "is a directory"),
    "run invalid toml": (["run", "bad.toml"], "not valid TOML"),
    "run typed toml": (["run", "typed.toml"], "platform.baseline"),
    "run unknown section file": (["run", "section.toml"], "sonar"),
    "run receiver key in file": (["run", "receiver.toml"], "receiver.alpha"),
    # run: receivers
    "run unknown receiver": (["run", "semicircle", "--set", "receiver=kalman"], "simulation.receiver"),
    "run key of another receiver": (["run", "semicircle", "--set", "receiver=lsq",
                                     "--set", "receiver.q_horizontal=5"], "receiver.q_horizontal"),
    "run missing fmu receiver": (["run", "semicircle", "--set", "receiver=fmu:none.fmu"], "simulation.receiver"),
    "run missing model receiver": (["run", "semicircle", "--set", "receiver=model:none.py"], "simulation.receiver"),
    "run model without a class": (["run", "semicircle", "--set", "receiver=model:nomodel.py"],
                                  "simulation.receiver"),
    "run model that fails": (["run", "semicircle", "--set", "receiver=model:broken.py"], "simulation.receiver"),
    "run model that exits": (["run", "semicircle", "--set", "receiver=model:exits.py"], "SystemExit"),
    # run: trajectory files
    "trajectory pass beyond memory": (["run", "semicircle", *T, "target.trajectory_file=long_pass.csv",
                                       "--set", "simulation.sampling_time=0.001"],
                                      "simulation.duration: 0 (one pass of target.trajectory_file"),
    "trajectory rows beyond 512": (["run", "semicircle", *T, "target.trajectory_file=many_rows.csv"],
                                   "at least 513 rows"),
    "trajectory missing": (["run", "semicircle", *T, "target.trajectory_file=none.csv"], "target.trajectory_file"),
    "trajectory nan": (["run", "semicircle", *T, "target.trajectory_file=nan_row.csv"], "target.trajectory_file"),
    "trajectory typo": (["run", "semicircle", *T, "target.trajectory_file=typo_row.csv"], "target.trajectory_file"),
    "trajectory backwards": (["run", "semicircle", *T, "target.trajectory_file=back_in_time.csv"],
                             "target.trajectory_file"),
    "trajectory header": (["run", "semicircle", *T, "target.trajectory_file=names.csv"], "target.trajectory_file"),
    "trajectory columns": (["run", "semicircle", *T, "target.trajectory_file=three.csv"], "target.trajectory_file"),
    "trajectory above surface": (["run", "semicircle", *T, "target.trajectory_file=above_surface.csv"],
                                 "target.trajectory_file"),
    "trajectory one row": (["run", "semicircle", *T, "target.trajectory_file=one_row.csv"],
                           "target.trajectory_file"),
    "trajectory directory": (["run", "semicircle", *T, "target.trajectory_file=adir"], "target.trajectory_file"),
    "waypoints text": (["run", "semicircle", *T, "target.waypoints=0 0 0 5; 1 x 1 5"], "target.waypoints"),
    # run: sound-speed profiles
    "profile text": (["run", "semicircle", *S, "acoustics.sound_speed_profile=ssp_text.csv"],
                     "acoustics.sound_speed_profile"),
    "profile too slow": (["run", "semicircle", *S, "acoustics.sound_speed_profile=ssp_slow.csv"],
                         "acoustics.sound_speed_profile"),
    "profile negative depth": (["run", "semicircle", *S, "acoustics.sound_speed_profile=ssp_negative.csv"],
                               "acoustics.sound_speed_profile"),
    "profile without header": (["run", "semicircle", *S, "acoustics.sound_speed_profile=ssp_noheader.csv"],
                               "acoustics.sound_speed_profile"),
    "profile nan": (["run", "semicircle", *S, "acoustics.sound_speed_profile=ssp_nan.csv"],
                    "acoustics.sound_speed_profile"),
    "profile unknown cast": (["run", "semicircle", *S, "acoustics.sound_speed_profile=ctd:nosuch"],
                             "acoustics.sound_speed_profile"),
    "profile table": (["run", "semicircle", *S, "acoustics.sound_speed_profile=table",
                       *S, "acoustics.sound_speed_table=0 1500; 10"], "acoustics.sound_speed_table"),
    # run: propagation and the site's water depth (the key and its allowed range in the one line)
    "propagation curved": (["run", "semicircle", *S, "acoustics.propagation=curved"],
                           "acoustics.propagation: 'curved' is not allowed; one of straight, ray"),
    "water depth negative": (["run", "semicircle", *S, "acoustics.propagation=ray", *S, "acoustics.water_depth=-1"],
                             "acoustics.water_depth: -1.0 is outside the allowed range [0, 11000] m"),
    "water depth 20000": (["run", "semicircle", *S, "acoustics.water_depth=20000"],
                          "acoustics.water_depth: 20000.0 is outside the allowed range [0, 11000] m"),
    "water depth above the diver": (["run", "semicircle", *S, "acoustics.propagation=ray", *S, "target.depth=30",
                                     *S, "acoustics.water_depth=20"],
                                    "acoustics.water_depth: 20 m is above the diver, target.depth (30 m); allowed: 0 "
                                    "(no surface or bottom reflection) or a depth in (30, 11000] m"),
    "water depth above a waypoint": (["run", "semicircle", *T, "target.waypoints=0 0 0 5; 10 5 5 40", *S,
                                      "acoustics.water_depth=20"],
                                     "acoustics.water_depth: 20 m is above the diver, the deepest waypoint of "
                                     "target.waypoints (40 m)"),
    "water depth above the transponders": (["run", "semicircle", *S, "platform.system=lbl", *S,
                                            "acoustics.water_depth=20"],
                                           "acoustics.water_depth: 20 m is above the deepest transducer (50 m); "
                                           "allowed: 0 (no surface or bottom reflection) or a depth in [50, 11000] m"),
    # run: engines, outputs, packages
    "run fmu engine without fmus": (["run", "semicircle", "--engine", "fmu", "--fmu-dir", "emptyfmus"], "fmu"),
    "run six beacons on the cross": (["run", "semicircle", "--set", "platform.beacons=6"], "platform.beacons"),
    "run 17 beacons": (["run", "semicircle", "--set", "platform.layout=circle", "--set", "platform.beacons=17"],
                       "platform.beacons"),
    "run 2 beacons": (["run", "semicircle", "--set", "platform.layout=circle", "--set", "platform.beacons=2"],
                      "platform.beacons"),
    "run beacons against offsets": (["run", "semicircle", "--set", "platform.layout=custom", "--set",
                                     "platform.beacons=4", "--set", "platform.beacon_offsets=1 0 1; 0 1 1; -1 0 1"],
                                    "platform.beacons"),
    "run two custom beacons": (["run", "semicircle", "--set", "platform.layout=custom",
                                "--set", "platform.beacon_offsets=1 0 1; 0 1 1"], "platform.beacon_offsets"),
    "fmus build 2 beacons": (["fmus", "build", "--beacons", "2", "--out", "newfmus"], "--beacons"),
    "fmus build fmi version 4": (["fmus", "build", "--fmi-version", "4", "--out", "newfmus"], "--fmi-version"),
    "run out is a file": (["run", "semicircle", "--out", "afile"], "--out"),
    # as root os.access says yes under /proc and /sys: the check must try a write
    "run out under /proc": (["run", "semicircle", "--out", "/proc/sblsim-run"], "--out"),
    "analyze out under /sys": (["analyze", "campaign", "--out", "/sys/sblsim-report"], "--out"),
    "run over an earlier run": (["run", "semicircle", "--out", "earlier_run"], "--force"),
    "run engine choice": (["run", "semicircle", "--engine", "matlab"], "--engine"),
    "run scenario and ssp": (["run", "semicircle", "--ssp", "notzip.ssp"], "run:"),
    "run missing ssp": (["run", "--ssp", "none.ssp"], "ssp"),
    "run ssp not a zip": (["run", "--ssp", "notzip.ssp"], "ssp"),
    "run export-log suffix": (["run", "semicircle", "--export-log", "log.txt"], "--export-log"),
    "run export-detections of an lbl": (["run", "semicircle", "--export-detections", "det"], "--export-detections"),
    "run export-detections under /proc": (["run", "semicircle", "--set", "platform.system=ilbl", "--set",
                                           "platform.layout=circle", "--set", "simulation.receiver=ekf-seq",
                                           "--export-detections", "/proc/det"], "--export-detections"),
    "run export-log over a file": (["run", "semicircle", "--export-log", "exported.csv"], "--force"),
    # replay
    "replay missing log": (["replay", "none.csv"], "log: no such file"),
    "replay clock jump": (["replay", "jump_log.csv"], "line 3: time_s 1 s is 4 s before line 2's 5 s"),
    "replay unparsable line": (["replay", "typo_log.csv"], "line 3: beacon_e_m: '1x' is not a number"),
    "replay unknown receiver": (["replay", "good_log.csv", "--receiver", "kalman"], "--receiver"),
    "replay truth backwards": (["replay", "good_log.csv", "--truth", "truth_back.csv"], "line 4: time_s 0.5 s"),
    "replay over an earlier replay": (["replay", "good_log.csv", "--out", "earlier_run"], "--force"),
    "replay a number with an underscore": (["replay", "underscore_log.csv"],
                                           "line 3: range_m: '1_0.0' is not a number"),
    "replay arabic-indic digits": (["replay", "arabic_log.csv"], "line 3: range_m: '\u0666' is not a number"),
    "replay a named pipe": (["replay", "fifo_log.csv"], "is not a regular file"),
    "replay a log naming a model": (["replay", "model_log.csv"], "simulation.receiver = 'model:exits.py'"),
    "replay a log naming an fmu": (["replay", "fmu_log.csv"], "never imports or loads from a log"),
    "replay a parquet log naming a model": (["replay", "model_log.parquet"], "simulation.receiver = 'model:exits.py'"),
    "replay nested config lines": (["replay", "deep_log.csv"], "nested deeper than"),
    "replay nested parquet metadata": (["replay", "deep_log.parquet"], "nested deeper than"),
    "replay nested --config": (["replay", "good_log.csv", "--config", "deep.toml"], "nested deeper than"),
    "replay a named pipe as --config": (["replay", "good_log.csv", "--config", "fifo.toml"], "not a regular file"),
    "run nested config": (["run", "deep.toml"], "nested deeper than"),
    "run a named pipe as config": (["run", "fifo.toml"], "not a regular file"),
    "run trajectory_file without trajectory file": (["run", "semicircle", "--set", "target.trajectory_file=traj.csv"],
                                                    "target.trajectory_file: given, but target.trajectory"),
    "run receiver step too short": (["run", "semicircle", "--set", "simulation.sampling_time=0.001",
                                     "--set", "simulation.ekf_rate_ratio=1000"],
                                    "simulation.ekf_rate_ratio: 1000 at simulation.sampling_time = 0.001 s"),
    "run export-log under /proc": (["run", "semicircle", "--export-log", "/proc/x.csv"], "--export-log"),
    "run export-log over its own time series": (["run", "semicircle", "--out", "o", "--export-log",
                                                 "o/timeseries.parquet"], "--export-log: 'o/timeseries.parquet'"),
    # campaign and studies
    "campaign missing study": (["campaign", "none.toml"], "study"),
    "campaign invalid study": (["campaign", "study_bad.toml"], "study"),
    "campaign unknown study key": (["campaign", "study_key.toml"], "study.colour"),
    "campaign level out of range": (["campaign", "study_level.toml"], "factors.loss.high"),
    "campaign equal levels": (["campaign", "study_same.toml"], "factors.b"),
    "campaign swapped levels": (["campaign", "study_swapped.toml"], "factors.b"),
    "campaign unknown factor key": (["campaign", "study_unknown_key.toml"], "factors.b.key"),
    "campaign zero replicates": (["campaign", "study_replicates.toml"], "study.replicates"),
    "campaign no scenarios": (["campaign", "study_noscenario.toml"], "study.scenarios"),
    "campaign negative seed": (["campaign", "study_seed.toml"], "study.seed"),
    "campaign design": (["campaign", "study_design.toml"], "study.design"),
    "campaign resolution": (["campaign", "study_resolution.toml"], "study.resolution"),
    "campaign generators": (["campaign", "study_generators.toml"], "study.generators"),
    "campaign unknown scenario": (["campaign", "study_scenario.toml"], "scenario"),
    "campaign bad profile in set": (["campaign", "study_set.toml"], "acoustics.sound_speed_profile"),
    "campaign receiver factor key": (["campaign", "study_alpha.toml"], "factors.a.key"),
    "campaign reserved factor name": (["campaign", "study_reserved.toml"], "factors[0].name"),
    "campaign receiver level": (["campaign", "study_receiver.toml"], "factors.rx.high"),
    "campaign chunks beyond memory": (["campaign", "study_memory.toml"],
                                      "simulation.duration: 100 s at T = 0.001 s is 100000 steps x 100000"),
    "campaign scheduler not an address": (["campaign", "study_ok.toml", "--scheduler", "garbage"], "--scheduler"),
    "campaign scheduler port 0": (["campaign", "study_ok.toml", "--scheduler", "tcp://127.0.0.1:0"],
                                  "--scheduler"),
    "campaign zero workers": (["campaign", "paper", "--workers", "0"], "--workers"),
    "campaign zero batch": (["campaign", "paper", "--batch", "0"], "--batch"),
    "campaign into a used folder": (["campaign", "study_ok.toml", "--out", "nonempty"], "--out"),
    "campaign paper into a used folder": (["campaign", "paper", "--out", "nonempty"], "--out"),
    "campaign resume damaged study": (["campaign", "paper", "--out", "campaign", "--resume"], "study.toml"),
    "campaign out under /proc": (["campaign", "study_ok.toml", "--out", "/proc/sblsim-campaign"], "--out"),
    # analyze
    "analyze nothing": (["analyze", "adir"], "runs.parquet"),
    "analyze corrupt runs": (["analyze", "campaign"], "runs.parquet"),
    "analyze missing folder": (["analyze", "nowhere"], "runs.parquet"),
    "analyze unknown transform": (["analyze", "campaign", "--transform", "sqrt"], "--transform"),
    # ssp
    "ssp out not .ssp": (["ssp", "export", "semicircle", "--out", "package.zip"], "--out"),
    "ssp fmi 3 with fmu dir": (["ssp", "export", "semicircle", "--fmi-version", "3", "--fmu-dir", "newfmus", "--out",
                                "package.ssp"], "--fmu-dir"),
    "ssp over a package": (["ssp", "export", "semicircle", "--out", "earlier.ssp"], "--force"),
    "ssp out under /sys": (["ssp", "export", "semicircle", "--out", "/sys/kernel/sblsim/s.ssp"], "--out"),
    "ssp bad value": (["ssp", "export", "semicircle", "--out", "new.ssp", "--set", "platform.baseline=-1"],
                      "platform.baseline"),
    # fmus and codegen
    "fmus validate empty": (["fmus", "validate", "emptyfmus"], "FMU not found"),
    "fmus build missing model": (["fmus", "build", "--model", "none.py", "--out", "newfmus"], "--model"),
    "fmus build model without class": (["fmus", "build", "--model", "nomodel.py", "--out", "newfmus"], "--model"),
    "fmus build out is a file": (["fmus", "build", "--out", "afile"], "--out"),
    "fmus build scenario without out": (["fmus", "build", "--scenario", "lbl-field"], "--out"),
    "fmus build scenario with model": (["fmus", "build", "--scenario", "lbl-field", "--model", "nomodel.py", "--out",
                                        "newfmus"], "--model"),
    "fmus build scenario with beacons": (["fmus", "build", "--scenario", "lbl-field", "--beacons", "6", "--out",
                                          "newfmus"], "--beacons"),
    "fmus build seed without scenario": (["fmus", "build", "--seed", "3", "--out", "newfmus"], "--seed"),
    "fmus build receiver without scenario": (["fmus", "build", "--receiver", "ukf", "--out", "newfmus"], "--receiver"),
    "fmus build scenario unknown": (["fmus", "build", "--scenario", "atlantis", "--out", "newfmus"], "scenario"),
    "fmus build scenario seed": (["fmus", "build", "--scenario", "lbl-field", "--seed", "-1", "--out", "newfmus"],
                                 "--seed"),
    "fmus build scenario unknown receiver": (["fmus", "build", "--scenario", "lbl-field", "--receiver", "kalman",
                                              "--out", "newfmus"], "--receiver"),
    "fmus build scenario fmu receiver": (["fmus", "build", "--scenario", "lbl-field", "--receiver",
                                          "fmu:emptyfmus/sblsim_platform.fmu.bak", "--out", "newfmus"], "--receiver"),
    "fmus build scenario latency": (["fmus", "build", "--scenario", "lbl-field", "--set", "receiver.latency=3",
                                     "--out", "newfmus"], "receiver.latency"),
    "fmus build scenario out is a file": (["fmus", "build", "--scenario", "lbl-field", "--out", "afile"], "--out"),
    "codegen unknown receiver": (["codegen", "receiver", "--receiver", "kalman", "--out", "code"], "--receiver"),
    "codegen used folder": (["codegen", "receiver", "--out", "nonempty"], "not an empty directory"),
    # compare and map
    "compare unknown receiver": (["compare", "semicircle", "--receivers", "ekf,kalman"], "--receivers"),
    "compare zero replicates": (["compare", "semicircle", "--replicates", "0"], "--replicates"),
    "compare foreign key": (["compare", "semicircle", "--set", "receiver.alpha=0.5"], "receiver.alpha"),
    "map negative extent": (["map", "semicircle", "--extent", "-1"], "--extent"),
    "map huge grid": (["map", "semicircle", "--step", "0.001"], "--step"),
    "map levels": (["map", "semicircle", "--levels", "1,x"], "--levels"),
    "map compare form": (["map", "semicircle", "--compare", "baseline=1,3"], "--compare"),
    "map compare value": (["map", "semicircle", "--compare", "platform.baseline=1,-3"], "platform.baseline"),
    "map over an earlier map": (["map", "semicircle", "--out", "earlier_map"], "--force"),
    # budget
    "budget one replicate": (["budget", "semicircle", "--replicates", "1"], "--replicates"),
    "budget unknown receiver": (["budget", "semicircle", "--receiver", "kalman"], "--receiver"),
    "budget compare form": (["budget", "semicircle", "--compare", "sigma_range=0.1,1"], "--compare"),
    "budget compare unknown key": (["budget", "semicircle", "--compare", "acoustics.sigma=0.1,1"],
                                   "acoustics.sigma"),
    "budget compare value": (["budget", "semicircle", "--compare", "platform.system=sbl,xbl"], "platform.system"),
    "budget over an earlier budget": (["budget", "semicircle", "--out", "earlier_budget"], "--force"),
    # design
    "design missing problem": (["design", "none.toml"], "design: no such file"),
    "design unknown built-in": (["design", "lbl-field-9km"], "neither a built-in design"),
    "design not toml": (["design", "d_bad.toml"], "is not valid TOML"),
    "design fifo": (["design", "fifo.toml"], "not a regular file"),
    "design too large": (["design", "d_big.toml"], "at most 1,048,576"),
    "design nested deep": (["design", "d_deep.toml"], "not valid TOML"),
    "design unknown section": (["design", "d_section.toml"], "unknown section [sonar]"),
    "design unknown key": (["design", "d_key.toml"], "work_area.colour"),
    "design value out of range": (["design", "d_range.toml"], "prescription.drms_m"),
    "design nan": (["design", "d_nan.toml"], "prescription.drms_m"),
    "design wrong type": (["design", "d_type.toml"], "prescription.coverage_pct"),
    "design short list": (["design", "d_length.toml"], "candidates.transponders"),
    "design swapped counts": (["design", "d_swapped.toml"], "candidates.transponders"),
    "design unknown grade": (["design", "d_grade.toml"], "candidates.gps[0]"),
    "design costs of other grades": (["design", "d_costs.toml"], "candidates.gps_cost"),
    "design flat polygon": (["design", "d_polygon.toml"], "seafloor.avoid[0]"),
    "design scenario path": (["design", "d_path.toml"], "design.scenario"),
    "design scenario file it names": (["design", "d_toml_path.toml"], "design.scenario"),
    "design set names a file": (["design", "d_set_file.toml"], "design.set: target.trajectory_file"),
    "design set names code": (["design", "d_set_model.toml"], "design.set: simulation.receiver"),
    "design set out of range": (["design", "d_set_bad.toml"], "platform.baseline"),
    "design name escapes": (["design", "d_name.toml"], "design.name"),
    "design floor above the vehicle": (["design", "d_floor.toml"], "seafloor.depth_m"),
    "design zero workers": (["design", "lbl-field-2km", "--workers", "0"], "--workers"),
    "design seed": (["design", "lbl-field-2km", "--seed", "-2"], "--seed"),
    "design out under /proc": (["design", "lbl-field-2km", "--out", "/proc/sblsim-design"], "--out"),
    "design over an earlier design": (["design", "lbl-field-2km", "--out", "earlier_design"], "--force"),
    "design scenario option": (["design", "lbl-field-2km", "--scenario", "none.toml"], "no such file"),
}


def _snapshot(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): (hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir")
            for p in sorted(folder.rglob("*"))}


def _prepare(folder: Path) -> None:
    folder.mkdir(parents=True)
    for name, text in FILES.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    with zipfile.ZipFile(folder / "emptyfmus" / "sblsim_platform.fmu.bak", "w"):
        pass
    for name in FILES:  # the earlier results are sblsim's own (their folders' manifests say so)
        if name.startswith("earlier_"):
            write_manifest(folder / Path(name).parent, [Path(name).name])
    import pyarrow as pa
    import pyarrow.parquet as pq

    for name, config in PARQUET.items():
        table = pa.table({"time_s": [0.1], "beacon_id": [1], "range_m": [6.0], "beacon_n_m": [1.0],
                          "beacon_e_m": [0.0], "beacon_d_m": [1.0], "depth_m": [2.0]})
        pq.write_table(table.replace_schema_metadata({b"sblsim.config": config.encode()}), folder / name)
    for name in FIFOS:
        os.mkfifo(folder / name)


def _command(args: list[str], folder: str, stdout: str, stderr: str) -> None:
    """A case's command in a process of its own (forked from the server that imported the CLI): in its folder, its
    output into two files, ended as ``python -m sblsim.orchestrator.cli`` ends (the exit status of ``main``, or
    of the SystemExit it raised; any other exception: its traceback and 1)."""
    import traceback

    from sblsim.orchestrator.cli import main

    os.chdir(folder)
    os.environ["SBLSIM_FMU_DIR"] = os.path.join(folder, "emptyfmus")
    for fd, name in ((1, stdout), (2, stderr)):
        os.dup2(os.open(name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC), fd)
    sys.argv = ["sblsim", *args]
    try:
        code = main(args)
    except SystemExit as stop:
        code = stop.code
        if code is not None and not isinstance(code, int):  # sys.exit("message"): the message, status 1
            print(code, file=sys.stderr)
            code = 1
    except BaseException:
        traceback.print_exc()
        code = 1
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code or 0)


#: Processes forked from one that imported the CLI, and the modules its commands import when they start, once (a
#: command's start-up, up to a second each, is not what is tested).
SERVER = multiprocessing.get_context("forkserver")
SERVER.set_forkserver_preload(["sblsim.orchestrator.cli", *(f"sblsim.orchestrator.{name}" for name in (
    "cosim.run", "campaign", "analysis", "montecarlo.budget", "maps", "logs.replay", "logs.receiver_log", "io.tables",
    "design.solve"))])


class _Case:
    """A case's command started in its prepared folder (the folder's contents before it, where its output goes)."""

    def __init__(self, case: str, folder: Path):
        _prepare(folder)
        self.case, self.folder, self.before = case, folder, _snapshot(folder)
        self.streams = folder.parent / f"{folder.name}.stdout", folder.parent / f"{folder.name}.stderr"
        self.process = SERVER.Process(target=_command, args=(list(CASES[case][0]), str(folder),
                                                             *map(str, self.streams)))
        self.process.start()
        self.started = time.monotonic()

    def outcome(self) -> tuple[subprocess.CompletedProcess, dict, dict]:
        self.process.join()
        out, err = (path.read_text() for path in self.streams)
        return (subprocess.CompletedProcess(CASES[self.case][0], self.process.exitcode, out, err), self.before,
                _snapshot(self.folder))


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    """Every case, run two at a time (each in a folder of its own, its output beside it).

    One thread starts and joins every process: multiprocessing's ``start`` polls the other running children,
    and a poll in one thread racing a ``join`` in another reads a forkserver child's exit status twice, one of
    them taking it as 255 (measured: 85 of 2,000 quick children started and joined from two threads)."""
    root = tmp_path_factory.mktemp("corpus")
    waiting, running, results = list(enumerate(CASES)), [], {}
    while waiting or running:
        while waiting and len(running) < 2:
            k, case = waiting.pop(0)
            running.append(_Case(case, root / f"case{k:03d}"))
        ready = multiprocessing.connection.wait([c.process.sentinel for c in running], timeout=1.0)
        for case in list(running):
            if case.process.sentinel in ready:
                results[case.case] = case.outcome()
                running.remove(case)
            elif time.monotonic() - case.started > 600:
                for other in running:
                    other.process.kill()
                    other.process.join()
                raise TimeoutError(f"{case.case}: still running after 600 s")
    return results


def test_the_corpus_is_large():
    assert len(CASES) >= 60


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_exit_2_and_changes_nothing(outcomes, case):
    proc, before, after = outcomes[case]
    _, needle = CASES[case]
    assert proc.returncode == 2, (proc.returncode, proc.stdout[-500:], proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("sblsim: error:"), proc.stderr
    assert needle in lines[0], (needle, lines[0])
    assert after == before, "the folder changed"
