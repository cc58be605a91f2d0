"""File formats, one parser per format: frames (`frames`), OTB box files (`otb_boxes`),
boxes.json (`boxes_json`), TUM trajectories (`tum`), CSV tables (`csv_table`), MOT Challenge
files (`mot`) and CVAT for video 1.1 XML (`cvat`); live input from a camera, a stream or a
paced video (`live`)."""
