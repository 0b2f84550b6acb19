"""The soak, short: a mixed bus with 10 % injected faults (bench/soak.py runs 100,000)."""

from drive_bridge.tools.soak import COUNTED_AS, run_soak, SoakSettings


def test_short_soak_meets_the_zeros_and_counts_every_fault_by_kind():
    # 0.2 s timeout: the 'slow' faults (140 ms) and the 'slow' mark (100 ms) keep wide
    # margins from the normal replies (a few ms on a pty) on a loaded test machine.
    report = run_soak(SoakSettings(transactions=1500, fault_rate=0.1, seed=7, timeout_s=0.2))
    text = '\n'.join(report.lines())
    assert report.transactions >= 1500, text
    assert report.crashes == 0, report.crash_texts
    assert report.unasked_writes == 0, report.unasked_texts
    assert report.repeated_starts == 0, text
    assert all(report.injected[kind] > 0 for kind in COUNTED_AS), text  # every kind ran
    assert report.faults_match, text
    assert report.commands['start acknowledged'] > 0 and report.commands['stop acknowledged'] > 0
    assert report.longest_gap_online_s < 5.0, text  # the dead device never stalls the others
