"""The paper's protocols and ours, returning self-describing xarray Datasets."""
