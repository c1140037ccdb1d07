"""Finding notes: a leak's or a supply sag's trade with the valve's parameters is said beside it
(a valve delay's correlation with the sensor lag, already in its ±, is not); a term declined at
the end of its search is said to want more than its cause describes."""

from __future__ import annotations

from diegocal.report.finding_notes import notes


def finding(cause: str, correlation: dict) -> dict:
    return {"cause": cause, "channel": "knee.ext", "extra": {"correlation": correlation}, "evidence": {}}


def test_a_leak_says_what_it_trades_with_strongest_first():
    text = notes(finding("chamber_leak", {"c4": 0.41, "c1": -0.83}))
    assert "trades with c1 (ρ = -0.83), c4 (ρ = +0.41)" in text
    assert "more than its ± says" in text


def test_a_valve_delay_or_a_leak_without_trades_adds_nothing():
    assert "trades" not in notes(finding("valve_delay", {"sensor_lag.lag_s": -0.7}))
    assert "trades" not in notes(finding("chamber_leak", {}))


def test_a_term_declined_at_the_end_of_its_search_is_said_to_want_more_than_its_cause():
    from diegocal.report.finding_notes import stand_in_text

    term = "transmission_backlash:joint2"
    f = {"cause": "unexplained", "channel": "joint2", "evidence": {
        "validation_gain": 0.4, "stand_in": {"term": term, "validation_gain": 0.4},
        "declined": {"term": term, "why": "its half_width ends at the end of its search"}}}
    text = stand_in_text(f)
    assert "was declined (its half_width ends at the end of its search)" in text
    assert "would stand in" not in text
