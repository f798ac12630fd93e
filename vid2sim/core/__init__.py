"""The vocabulary every stage shares: the scenario model, the camera, ENU frames, boxes, vehicle outlines, polylines, tables, the lead rule, the records between stages."""
