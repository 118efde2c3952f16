"""The printed bolus: the shell over the skin, closed solids, parts with connectors, engraved labels."""
