"""The words of a diagnosis's report pages that are not drawn from the file: table notes and what
is said where a finding records no runner-up or no curve."""

CHANNEL_NOTE = (
    "RMSE on the held-out blocks, per channel, before and after adding the findings. '0 (exact)': the baseline "
    "reproduces the channel exactly (a pot that alone fixes its joint's angle), so no relative change is given."
)


#: Said where a finding records no runner-up (the round did test other candidates, in general)
NO_RUNNERS = {
    "term": "No runner-up is recorded for this finding: the round's other candidates were added with it or could "
    "not be scored beside it (their columns already in the model's).",
    "unexplained": "Structure that no term explains records no runner-up of its own: the round's candidates are "
    "listed with the findings they were tested for.",
}


RUNNERS_NOTE = (
    "The round's other candidate terms, fitted on the training blocks, scored on the validation blocks "
    "(validation gain: the share of their error a candidate removes); significant: t over the threshold (which "
    "holds the family-wise false-alarm rate) and a gain of at least min_gain; a significant one not added: the "
    "chosen term explains more of its channel's error (less on its channel, or less refitted: both refitted), or "
    "it acts elsewhere (next round)."
)


#: Said of a finding whose file does not hold the round's other candidates (``runners_up`` absent).
NOT_STORED = (
    "Runners-up: not stored in this file (the diagnosis that wrote it did not keep the round's other candidates)."
)


#: What a finding without an evidence curve shows instead of an empty plot.
NO_CURVE = (
    "No residual curve: this finding was not chosen from the residual binned against one variable (a data "
    "fault whose readings are written off, or a cause tried whole, such as a mocap clock seconds off); its "
    "held-out RMSE above is its evidence."
)
