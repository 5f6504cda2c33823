"""Data-generation pipelines: tracking -> bank -> motion export -> flow -> simulated scans."""
