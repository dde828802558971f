from layerskin_exp.types import StreamHealth


def test_stream_health_counts_gaps_duplicates_and_reordering():
    h = StreamHealth()
    last = None
    for seq in [0, 1, 2, 5, 5, 4, 6]:
        h.observe_seq(last, seq)
        last = max(seq, last) if last is not None else seq
    assert h.received == 7
    assert h.lost == 2  # 3 and 4 missing when 5 arrived
    assert h.duplicate == 1
    assert h.out_of_order == 1
