"""Options values: each option declared once, as a field of a frozen dataclass.

:mod:`mifaces.options.fields` describes a field (its default, and in its metadata its help, its
valid range or choices, its command-line flag), validates a value by those descriptions and
writes it as a JSON record; every options value uses it: :class:`mifaces.reflectance.FitOptions`,
:class:`mifaces.refine.ShapeRefineSchedule` and :class:`mifaces.options.measure.MeasureOptions`
(the main job's, which holds the other two). :func:`mifaces.cli.options.option_flags` turns the
same descriptions into the commands' flags.

Nothing is imported here: :mod:`mifaces.options.fields` sits below every stage, and
:mod:`mifaces.options.measure` above them.
"""
