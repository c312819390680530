// kinemo studio: the 3D views drawn off the page's main thread (render.js
// says why and what the messages are). A frame is drawn as soon as the
// messages queued before it are handled (the page sends one at a time), not
// at the worker's next animation frame: that would add up to a frame
// interval to what one sees live.
import { createRenderHost } from '/static/render.js';

const handle = createRenderHost((m) => self.postMessage(m), (draw) => setTimeout(draw, 0));
self.onmessage = (e) => handle(e.data);
