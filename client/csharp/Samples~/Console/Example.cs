// The package's example: lists a gmr-server's motions, then prints a few frames
// of one seen with another root, in Unity's conventions.
//   mcs -out:example.exe -r:Gmr.Runtime.dll Example.cs && mono example.exe [HOST [PORT [MOTION [ROOT]]]]
using System;
using System.Threading;

public static class Example
{
    public static int Main(string[] args)
    {
        string host = args.Length > 0 ? args[0] : "127.0.0.1";
        int port = args.Length > 1 ? int.Parse(args[1]) : 7400;
        try
        {
            using (var client = Gmr.Client.Connect(host, port))
            {
                Gmr.MotionInfo[] motions = client.ListMotions();
                foreach (var m in motions)
                    Console.WriteLine("{0}: {1} joints, {2} frames at {3:F1} Hz", m.Name, m.JointCount, m.FrameCount, 1.0 / m.FrameTime);
                string motion = args.Length > 2 ? args[2] : motions[0].Name;
                uint view = client.CreateView(motion);
                // Unity's conventions are in metres when the library knows the motion's unit.
                string unit = "file units (the library does not know this motion's unit)";
                foreach (var m in motions)
                    if (m.Name == motion && m.MetresPerUnit > 0) unit = "m";
                if (args.Length > 3) client.ShiftRoot(view, args[3]);
                var options = new Gmr.SubscribeOptions { Conventions = Gmr.Conventions.Unity, LocalTransforms = true, MaxFrames = 10 };
                using (var sub = client.Subscribe(view, options))
                {
                    int shown = 0;
                    var deadline = DateTime.UtcNow.AddSeconds(10);
                    while (shown < 5 && !sub.Ended && DateTime.UtcNow < deadline)
                    {
                        if (!sub.Poll()) { Thread.Sleep(5); continue; }
                        Console.WriteLine("frame {0}: {1} ({2:F3}, {3:F3}, {4:F3}) {5}, latency {6:F2} ms", sub.FrameIndex,
                                          sub.Joints[0].Name, sub.Positions[0], sub.Positions[1], sub.Positions[2], unit,
                                          sub.LatencyMs());
                        shown++;
                    }
                }
            }
            return 0;
        }
        catch (Gmr.GmrException e)
        {
            Console.Error.WriteLine("gmr: " + e.Message);
            return 1;
        }
    }
}
