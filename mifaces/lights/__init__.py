"""Lights as a rendered scene sees them: Mitsuba emitters and environments."""
