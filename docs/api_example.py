import jaxgest as jg

tgst = jg.tgst.load("runs/tgst")  # a workdir of `jaxgest tgst train`; the model gets style.bvh + its mirror
styled = tgst.transfer("content.bvh", "style.bvh", method="soft")  # or "coherent", style_input="as-is"
jg.save_bvh(styled, "styled.bvh")

zeggs = jg.zeggs.load("runs/zeggs")  # a workdir of `jaxgest zeggs train`
gestures = zeggs.generate("speech.wav", ["calm.bvh", "happy.bvh"], weights=[0.5, 0.5], seed=0)
jg.save_bvh(gestures, "gestures.bvh")
