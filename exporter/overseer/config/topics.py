"""The diagnostics topics every transport follows, by their last name segment."""

DIAGNOSTIC_TOPICS = ("diagnostics_agg", "diagnostics")
