"""datasets: trajectory readers/writers, cut-in extraction, embedded data, surface fitting."""
