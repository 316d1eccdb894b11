"""What a run reads and writes: files, not physics.

What belongs here: ParaView snapshots (:mod:`.snapshots`), checkpoints (:mod:`.checkpoint`), the progress line
(:mod:`.progress`), the channel and zone columns of the time series (:mod:`.channel`), the run's own pictures
(:mod:`.plots`) and the reader of initial-droplet lists (:mod:`.droplet_list`). Nothing here changes the state of a
run.
"""
