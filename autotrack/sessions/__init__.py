"""Sessions in MCAP: schemas and topics, recorder, reader, exports."""
