"""The measurement report: its figures, pictures, HTML page and a batch's population report."""
