"""The ``mifaces`` command line (:mod:`.commands`) and its options (:mod:`.options`)."""
