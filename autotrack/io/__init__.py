"""File formats, one parser per format: frames (`frames`), OTB box files (`otb_boxes`),
boxes.json (`boxes_json`), TUM trajectories (`tum`) and CSV tables (`csv_table`)."""
