"""The main job end to end (:mod:`.measure`) and many captures at once (:mod:`.batch`)."""
