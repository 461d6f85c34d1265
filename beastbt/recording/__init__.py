"""Every run recorded: the recorder and its writer process, the wire between them, the channel schemas, the reader, replay, report and the list of runs."""
