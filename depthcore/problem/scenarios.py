"""The paper's experiments (Figures 2-6) and the numbers it reports, in one place.

Recommended import: ``from depthcore.problem.scenarios import SCENARIOS, REPORTED``.
"""

from __future__ import annotations

from dataclasses import dataclass

from depthcore.problem.gaussian import Gaussian, paper_prior
from depthcore.problem.model import noise_free_state

#: The measurements of Figures 2, 4, 5 and 6, Eq. (17).
MU_17 = (-3 / 10, 0.0, 1 / 5)
#: The measurements of Figure 3, Eq. (18).
MU_18 = (-1 / 4, 0.0, 1 / 5)
#: The noise level of most experiments (radians); "about 5 pixels".
RHO_200 = 1 / 200
#: The noise level of Figure 5; "about 1 pixel".
RHO_500 = 1 / 500


@dataclass(frozen=True)
class Scenario:
    """One of the paper's experiments.

    Attributes
    ----------
    key : str
        ``"fig2"`` ... ``"fig6"``.
    figure : int
    quantity : str
        The marginal the paper plots: ``"depth"`` or ``"velocity"``.
    mu : tuple of float
        Measurements ``(mu1, mu2, mu3)``.
    rho : float
        Noise standard deviation (radians).
    depth_offset : float
        Added to the depth of the paper's prior mean (Figure 6 uses 2).
    description : str
    """

    key: str
    figure: int
    quantity: str
    mu: tuple
    rho: float
    depth_offset: float
    description: str

    @property
    def c(self):
        """The noise-free state at time 3, Eq. (7)."""
        return noise_free_state(self.mu)

    @property
    def prior(self) -> Gaussian:
        """The paper's prior, mean ``(c1 - 2 c3, c2 - 2 + offset, 0)``, covariance ``1000 I``."""
        return paper_prior(self.c, self.depth_offset)


#: The paper's five experiments by key (``"fig2"`` ... ``"fig6"``).
SCENARIOS = {
    s.key: s
    for s in (
        Scenario(
            "fig2",
            2,
            "depth",
            MU_17,
            RHO_200,
            0.0,
            "Depth marginals, measurements (17), rho = 1/200",
        ),
        Scenario(
            "fig3",
            3,
            "depth",
            MU_18,
            RHO_200,
            0.0,
            "Depth marginals, measurements (18), rho = 1/200",
        ),
        Scenario(
            "fig4",
            4,
            "velocity",
            MU_17,
            RHO_200,
            0.0,
            "Velocity marginals, measurements (17), rho = 1/200",
        ),
        Scenario(
            "fig5",
            5,
            "depth",
            MU_17,
            RHO_500,
            0.0,
            "Depth marginals, measurements (17), rho = 1/500",
        ),
        Scenario(
            "fig6",
            6,
            "depth",
            MU_17,
            RHO_200,
            2.0,
            "Depth marginals, measurements (17), rho = 1/200, prior depth two units higher",
        ),
    )
}

#: The means and standard deviations the paper prints, as ``(mean, sd)`` of the
#: depth marginal, with the scan's text where it is garbled. Figures 4-6 carry
#: no numbers.
REPORTED = {
    "fig2": {
        "optimal": {"depth": (6.47, 0.80)},
        "second_order": {"depth": (6.00, 0.62)},
        "ekf": {"depth": (6.00, 0.16)},
    },
    "fig3": {
        # The scan reads "E(p_oy) = 6745  sigma_oy = 67.45": a decimal point is
        # lost in the mean, and the SD repeats the mean's digits.
        "optimal": {"depth": (67.45, 67.45)},
        "second_order": {"depth": (10.00, 2.20)},
        "ekf": {"depth": (10.00, 0.28)},
    },
}

#: The scan's literal text where it garbles a reported value, as ``(mean, sd)``
#: strings: Figure 3's optimal mean is printed without its decimal point.
SCAN_TEXT = {"fig3": {"optimal": {"depth": ("6745", "67.45")}}}

#: Decimal places the paper prints its means and SDs with.
REPORTED_DECIMALS = 2

#: Values from the paper that the book's prose quotes in words rather than
#: gluing (a number inside a quotation from the paper, or a setting of the
#: paper's experiment described in words), with where the paper gives them.
#: ``tests/test_prose_numbers.py`` allows these strings, and only these, in prose.
#: The highest legible label on the density axis of the scanned Figure 5.
FIG5_SCAN_DENSITY_AXIS = 0.8

PROSE_QUOTES = {
    "512 pixels": "Experiments: the image is 512 x 512 pixels with a 30 degree field of view",
    '"about 5 pixels"': "Experiments: rho = 1/200 rad is about 5 pixels",
    '"about 1 pixel"': "Experiments: rho = 1/500 rad is about 1 pixel (Figure 5)",
}

#: Values quoted from the paper (and one from the literature) inside
#: mathematics, as the pages write them in LaTeX, with where they come from.
#: ``tests/test_prose_numbers.py`` allows these strings, and only these (beside
#: single digits, exponents and indices), to hold numbers in the mathematics.
MATH_QUOTES = {
    "1/200": "Experiments: the noise level of Figures 2-4 and 6, rho = 1/200",
    "1/500": "Figure 5: the noise level rho = 1/500",
    "1000\\,I": "Experiments: the prior covariance 1000 I",
    "512 \\times 512": "Experiments: the image is 512 x 512 pixels",
    "256": "Experiments: half the image's 512 pixels, over tan 15 degrees",
    "512 / (\\pi/6)": "Experiments: 512 pixels across the 30 degree (pi/6) field of view",
    "15°": "Experiments: the 30 degree field of view, 15 degrees either side",
    "30°": "Experiments: the 30 degree field of view",
    "6/5": "Measurements (17): the noise-free state c = (6/5, 6, 6/5)",
    "\\tfrac{3}{10}": "Measurements (17): mu_1 = -3/10",
    "c_2 = 10": "Measurements (18): the noise-free depth of Figure 3",
    "(2, 10, 2)": "Measurements (18): the noise-free state c = (2, 10, 2) of Figure 3",
    "2.38/\\sqrt{3}": "Roberts, Gelman and Gilks (1997): a random-walk proposal's scale "
    "2.38/sqrt(d), here d = 3",
}
