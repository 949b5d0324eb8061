"""Validation on the shared real data: one study per dataset and the report renderer."""
