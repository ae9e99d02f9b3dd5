#!/usr/bin/python3
"""scripts/steady_state.py on signals whose answer is known exactly (issue 19's tests)."""
import math
import os
import sys
import unittest

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "scripts"))
import steady_state as ss  # noqa: E402

DT = 1e-5
T = np.arange(0, 0.4, DT)  # 40 000 samples, 400 periods of 1 kHz


class SteadyState(unittest.TestCase):
    def test_two_incommensurate_lines_are_quasi_periodic_to_1e_6(self):
        f1, f2 = 1000.0, 1000.0 * math.sqrt(2)
        x = np.sin(2 * np.pi * f1 * T + 0.3) + 0.5 * np.sin(2 * np.pi * f2 * T + 1.1)
        r = ss.analyse(x, T)
        self.assertEqual(r["verdict"], "quasi-periodic", r["evidence"])
        got = sorted(r["lines"][np.argsort(-r["amplitudes"])[:2]])
        self.assertLess(abs(got[0] / f1 - 1), 1e-6)
        self.assertLess(abs(got[1] / f2 - 1), 1e-6)

    def test_a_wave_with_harmonics_is_periodic(self):
        f = 1234.5
        x = np.sin(2 * np.pi * f * T) + 0.3 * np.sin(6 * np.pi * f * T + 0.2) + 0.1 * np.sin(10 * np.pi * f * T)
        r = ss.analyse(x, T)
        self.assertEqual(r["verdict"], "periodic", r["evidence"])
        self.assertLess(abs(r["bases"][0] / f - 1), 1e-7)
        names = {n for n in r["names"]}
        self.assertTrue({"1 f1", "3 f1", "5 f1"} <= names, names)

    def test_a_stronger_second_harmonic_keeps_the_fundamental_as_base(self):
        x = 0.4 * np.sin(2 * np.pi * 777.7 * T) + np.sin(4 * np.pi * 777.7 * T + 0.5)
        r = ss.analyse(x, T)
        self.assertEqual(r["verdict"], "periodic", r["evidence"])
        self.assertLess(abs(r["bases"][0] / 777.7 - 1), 1e-7)

    def test_white_noise_is_broadband(self):
        x = np.random.default_rng(1).standard_normal(len(T))
        self.assertEqual(ss.analyse(x, T)["verdict"], "broadband")

    def test_names_that_could_be_chance_make_the_verdict_unresolved(self):
        # the brake's lines after 50 periods (resolution 388 Hz): every line named, 16 573 Hz as
        # "2 f1" of 7 741 Hz; the C++ twin is SteadyState.NamesThatCouldBeChanceMakeTheVerdictUnresolved
        f = np.array([16572.68, 33129.27, 49621.27, 7741.43, 66340.89, 40864.54, 57943.24, 24869.60])
        amp = np.array([3.53e-5, 4.65e-6, 4.45e-6, 3.04e-6, 2.79e-6, 1.43e-6, 1.20e-6, 1.11e-6])
        p = float(np.sum(amp ** 2 / 2))
        self.assertEqual(ss.classify(f, amp, p, p, 388.0)[0], "unresolved")
        self.assertEqual(ss.classify(f, amp, p, p, 1.0)[0], "broadband")
        h, ha = np.array([100.0, 200.0, 300.0]), np.array([1.0, 0.5, 0.2])
        self.assertEqual(ss.classify(h, ha, 0.645, 0.645, 1.0)[0], "periodic")
        self.assertEqual(ss.classify(h, ha, 0.645, 0.645, 5.0)[0], "unresolved")

    def test_rms_interval_contains_the_exact_value(self):
        # sine of amplitude A plus AR(1) noise e_k = phi e_{k-1} + s w_k: RMS^2 = A^2/2 + s^2/(1 - phi^2)
        A, phi, s = 1.0, 0.9, 0.3
        exact = math.sqrt(A * A / 2 + s * s / (1 - phi * phi))
        inside = 0
        for seed in range(10):
            w = np.random.default_rng(seed).standard_normal(len(T))
            e = np.zeros(len(T))
            e[0] = w[0] * s / math.sqrt(1 - phi * phi)  # stationary from the start
            for k in range(1, len(T)):
                e[k] = phi * e[k - 1] + s * w[k]
            lv = ss.levels(np.sin(2 * np.pi * 1000 * T) * A + e)
            inside += lv["rms_lo"] <= exact <= lv["rms_hi"]
        self.assertGreaterEqual(inside, 8)  # a 95 % interval: 10 of 10 expected, 8 allowed

    def test_the_start_up_is_dropped(self):
        tau = 0.02
        x = 5 * np.exp(-T / tau) * np.sin(2 * np.pi * 700 * T) + np.sin(2 * np.pi * 1000 * T)
        cut = ss.mser_cut(x)
        self.assertGreater(T[cut], 2 * tau)   # the decaying part (25x the steady power at t = 0) is gone
        self.assertLess(T[cut], 0.2)          # and no more than half of the record


if __name__ == "__main__":
    unittest.main()
