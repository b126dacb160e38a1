"""jaxgest experiments: one folder per question, one config file per run, one driver.

    python -m experiments run CONFIG... [--quick]     train, evaluate, write a stamped results file
    python -m experiments table NAME [--quick]         regenerate a README table from its results files
    python -m experiments list                         every config and table

Run from the root of a clone (``python -m`` puts it on the path); see experiments/README.md.
"""
